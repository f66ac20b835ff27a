# Sourced by scripts/test: the system browser the console's browser tests drive
# (Debian's chromium and chromium-driver). Installed when absent and possible; else
# the browser tests skip, saying why (SAIM_NO_BROWSER).
if [ ! -x /usr/bin/chromium ] || [ ! -x /usr/bin/chromedriver ]; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing chromium and chromium-driver for the browser tests (apt-get)..." >&2
    if ! (DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver >/tmp/saim-apt.log 2>&1 \
          || { apt-get update -q >>/tmp/saim-apt.log 2>&1 \
               && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver >>/tmp/saim-apt.log 2>&1; }); then
      export SAIM_NO_BROWSER="apt-get install chromium chromium-driver failed (see /tmp/saim-apt.log)"
    fi
  else
    export SAIM_NO_BROWSER="no /usr/bin/chromium and not root with apt-get to install it"
  fi
fi
