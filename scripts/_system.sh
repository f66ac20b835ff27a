# Sourced by scripts/test and scripts/netns-hosts: the system tools the namespaced-host tests
# use (saim_mesh/net/netns.py): iproute2 (`ip netns`, `tc`) and nftables (`nft`, for silent cuts).
# Installed when absent and possible (root with apt-get); else one line says what is missing:
# without `ip` those tests skip, without `nft` cuts fall back to detaching bridge ports.
_saim_missing=()
command -v ip >/dev/null 2>&1 && command -v tc >/dev/null 2>&1 || _saim_missing+=(iproute2)
command -v nft >/dev/null 2>&1 || _saim_missing+=(nftables)
if [ "${#_saim_missing[@]}" -gt 0 ]; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing ${_saim_missing[*]} for the namespaced-host tests (apt-get)..." >&2
    if ! (DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${_saim_missing[@]}" >/tmp/saim-apt-system.log 2>&1 \
          || { apt-get update -q >>/tmp/saim-apt-system.log 2>&1 \
               && DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${_saim_missing[@]}" >>/tmp/saim-apt-system.log 2>&1; }); then
      echo "could not install ${_saim_missing[*]} (see /tmp/saim-apt-system.log): namespaced-host tests may skip" >&2
    fi
  else
    echo "missing ${_saim_missing[*]} and not root with apt-get: namespaced-host tests may skip" >&2
  fi
fi
unset _saim_missing
