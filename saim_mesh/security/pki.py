"""A small certificate authority for the mesh: one CA and one leaf certificate per role
(CN = role name), all ECDSA P-256, made with the `cryptography` package.

  ca.pem, ca.key        self-signed CA (CA:true, keyCertSign)
  NAME.pem, NAME.key    leaf: CN=NAME, SAN IP:127.0.0.1 + DNS:localhost (+ the addresses and
                        names of the host it runs on: `sans`, from a deployment file),
                        EKU serverAuth + clientAuth (every peer listens and connects)
  NAME.sign.pem         NAME's Ed25519 signing key (authority that survives relays: sign.py)
  signers.json          every identity's Ed25519 public key

Key files are PKCS#8 PEM, unencrypted (Zenoh cannot read encrypted keys), mode 600.
`make_pki` is idempotent: it keeps the CA and every leaf that is still valid, signed by
this CA and matches its key, and makes what is missing.

CLI: python -m saim_mesh.security.pki SCENARIO OUT_DIR [--units U ...] [--days N]
"""
from __future__ import annotations

import argparse
import datetime as dt
import ipaddress
import os
import re
import sys
import tempfile
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

CA_NAME = "ca"
CA_CN = "saim-mesh CA"   # + a random suffix: two CAs never share a name (clearer TLS errors)
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
MARGIN = dt.timedelta(hours=1)   # a leaf expiring sooner than this is made again


class SecurityError(ValueError):
    """A certificate, key or CA file is missing, unreadable or wrong; or an identity
    is not one the access-control rules know."""


# ---------------------------------------------------------------------------- files

def _now() -> dt.datetime:
    return dt.datetime.now(dt.timezone.utc)


def _write(path: Path, data: bytes, mode: int) -> None:
    """Atomic write (temporary file + rename) with the mode set before any byte lands."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    os.chmod(path, mode)


def _key_bytes(key) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise SecurityError(f"{path}: file missing") from None
    except IsADirectoryError:
        raise SecurityError(f"{path}: is a directory, not a PEM file") from None
    except OSError as e:
        raise SecurityError(f"{path}: cannot read ({e.strerror or e})") from None


def _load_certs(path: Path) -> list[x509.Certificate]:
    data = _read(path)
    if b"-----BEGIN CERTIFICATE-----" not in data:
        raise SecurityError(f"{path}: not a PEM certificate file")
    try:
        return x509.load_pem_x509_certificates(data)
    except ValueError as e:
        raise SecurityError(f"{path}: bad PEM certificate ({e})") from None


def _load_key(path: Path):
    data = _read(path)
    if b"-----BEGIN" not in data or b"PRIVATE KEY-----" not in data:
        raise SecurityError(f"{path}: not a PEM private key file")
    if b"ENCRYPTED" in data:
        raise SecurityError(f"{path}: encrypted private key (Zenoh needs it unencrypted)")
    try:
        return serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError) as e:
        raise SecurityError(f"{path}: bad PEM private key ({e})") from None


def check_files(paths) -> None:
    """Raise SecurityError naming the first file that is missing, unreadable or not PEM
    (a private key if its content says so, else one or more certificates).

    Zenoh's connecting side says nothing about bad files: it retries forever."""
    for p in paths:
        p = Path(p)
        head = _read(p)
        if b"PRIVATE KEY-----" in head:
            _load_key(p)
        else:
            _load_certs(p)


def _same_key(cert: x509.Certificate, key) -> bool:
    pub = serialization.PublicFormat.SubjectPublicKeyInfo
    return (cert.public_key().public_bytes(serialization.Encoding.DER, pub)
            == key.public_key().public_bytes(serialization.Encoding.DER, pub))


def _cn(cert: x509.Certificate) -> str | None:
    a = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    return str(a[0].value) if a else None


def _signed_by(cert: x509.Certificate, ca: x509.Certificate) -> bool:
    try:
        cert.verify_directly_issued_by(ca)
        return True
    except (ValueError, TypeError, InvalidSignature):
        return False


def _paths(out_dir: Path, name: str) -> tuple[Path, Path]:
    return out_dir / f"{name}.pem", out_dir / f"{name}.key"


def check_identity(pki_dir: str | Path, name: str) -> tuple[Path, Path, Path]:
    """Check the CA and NAME's certificate and key before Zenoh opens them: readable PEM,
    key matching the certificate, CN = NAME, signed by the CA, valid now.
    Returns (ca.pem, NAME.pem, NAME.key) as absolute paths."""
    d = Path(pki_dir).resolve()
    ca_pem = d / f"{CA_NAME}.pem"
    cert_p, key_p = _paths(d, name)
    check_files([ca_pem, cert_p, key_p])
    ca = _load_certs(ca_pem)[0]
    cert = _load_certs(cert_p)[0]
    if not _same_key(cert, _load_key(key_p)):
        raise SecurityError(f"{key_p}: private key does not match {cert_p}")
    if _cn(cert) != name:
        raise SecurityError(f"{cert_p}: CN is {_cn(cert)!r}, expected {name!r}")
    if not _signed_by(cert, ca):
        raise SecurityError(f"{cert_p}: not signed by the CA in {ca_pem}")
    now = _now()
    for c, p in ((ca, ca_pem), (cert, cert_p)):
        if not c.not_valid_before_utc <= now <= c.not_valid_after_utc:
            raise SecurityError(f"{p}: not valid now (valid {c.not_valid_before_utc:%Y-%m-%d %H:%M} "
                                f"to {c.not_valid_after_utc:%Y-%m-%d %H:%M} UTC)")
    return ca_pem, cert_p, key_p


# ---------------------------------------------------------------------------- making

def _new_key():
    return ec.generate_private_key(ec.SECP256R1())


def _make_ca(days: int):
    key = _new_key()
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"{CA_CN} {os.urandom(4).hex()}")])
    now = _now()
    ski = x509.SubjectKeyIdentifier.from_public_key(key.public_key())
    cert = (x509.CertificateBuilder()
            .subject_name(name).issuer_name(name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(minutes=5))
            .not_valid_after(now + dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False,
                                         key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, key_cert_sign=True, crl_sign=True,
                                         encipher_only=False, decipher_only=False), critical=True)
            .add_extension(ski, critical=False)
            .sign(key, hashes.SHA256()))
    return cert, key


LOCAL_SANS = ("127.0.0.1", "localhost")


def _san_entry(text: str) -> x509.GeneralName:
    """An IP address (v4 or v6) as IP:, anything else as DNS:."""
    try:
        return x509.IPAddress(ipaddress.ip_address(text))
    except ValueError:
        return x509.DNSName(text)


def _san_set(cert: x509.Certificate) -> set[str]:
    try:
        ext = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return set()
    return {str(a) for a in ext.get_values_for_type(x509.IPAddress)} | set(ext.get_values_for_type(x509.DNSName))


def _norm_sans(extra) -> list[str]:
    """Loopback first (every process reaches its own host's router there too), then the
    host's addresses and names, each once; an address in its canonical text form."""
    out: list[str] = []
    for x in (*LOCAL_SANS, *(extra or ())):
        x = str(x).strip()
        try:
            x = str(ipaddress.ip_address(x))
        except ValueError:
            if not x or not re.fullmatch(r"[A-Za-z0-9*]([A-Za-z0-9.-]*[A-Za-z0-9])?", x):
                raise SecurityError(f"bad subject alternative name {x!r}: an IP address or a DNS name") from None
        if x not in out:
            out.append(x)
    return out


def _make_leaf(name: str, ca: x509.Certificate, ca_key, days: int, sans=()):
    key = _new_key()
    now = _now()
    not_after = min(now + dt.timedelta(days=days), ca.not_valid_after_utc)
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(ca.subject)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(minutes=5))
            .not_valid_after(not_after)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False,
                                         key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, key_cert_sign=False, crl_sign=False,
                                         encipher_only=False, decipher_only=False), critical=True)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH,
                                                  ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False)
            .add_extension(x509.SubjectAlternativeName([_san_entry(x) for x in _norm_sans(sans)]), critical=False)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()),
                           critical=False)
            .sign(ca_key, hashes.SHA256()))
    return cert, key


def _leaf_ok(name: str, cert_p: Path, key_p: Path, ca: x509.Certificate, sans=()) -> bool:
    if not (cert_p.is_file() and key_p.is_file()):
        return False
    try:
        cert = _load_certs(cert_p)[0]
        key = _load_key(key_p)
    except SecurityError:
        return False
    now = _now()
    return (_cn(cert) == name and _signed_by(cert, ca) and _same_key(cert, key) and _san_set(cert) == set(sans)
            and cert.not_valid_before_utc <= now and cert.not_valid_after_utc > now + MARGIN)


def make_pki(out_dir: str | Path, names: list[str], days: int = 30, *, ca_days: int | None = None,
             echo=None, sans: dict[str, list[str]] | None = None) -> dict[str, tuple[Path, Path]]:
    """Make (or reuse) the CA in OUT_DIR and one certificate + key per name.

    The CA is made when ca.pem or ca.key is absent (every leaf is then made again);
    a CA that is present but unreadable, mismatched or expired raises SecurityError
    (remove both files to start a new one). A leaf is kept when it is valid for at least
    another hour, signed by this CA and matches its key; otherwise it is made again,
    valid `days` days (never past the CA, valid `ca_days`, default max(365, days)).
    Each name also gets an Ed25519 signing key (kept when readable) and signers.json
    lists every one (`sign.make_keys`). `sans`: name -> the addresses (IP) and DNS names
    of the host it runs on, put in its certificate beside 127.0.0.1 and localhost (a
    process listening on a host's address must show it: the connecting side checks it);
    a leaf whose names differ from these is made again.
    Returns {name: (NAME.pem, NAME.key)} as absolute paths; `echo` gets one line per file."""
    say = echo or (lambda _line: None)
    want = {n: _norm_sans((sans or {}).get(n, ())) for n in names}
    for n in names:
        if not NAME_RE.match(n) or n == CA_NAME:
            raise SecurityError(f"bad identity name {n!r} (letters, digits, '.', '_', '-'; not {CA_NAME!r})")
    if days <= 0:
        raise SecurityError(f"days must be positive, not {days}")
    d = Path(out_dir).resolve()
    d.mkdir(parents=True, exist_ok=True)
    ca_pem, ca_key_p = _paths(d, CA_NAME)
    if ca_pem.exists() and ca_key_p.exists():
        ca = _load_certs(ca_pem)[0]
        ca_key = _load_key(ca_key_p)
        if not _same_key(ca, ca_key):
            raise SecurityError(f"{ca_key_p}: does not match {ca_pem}; remove both to make a new CA")
        if ca.not_valid_after_utc <= _now() + MARGIN:
            raise SecurityError(f"{ca_pem}: CA expired or expiring ({ca.not_valid_after_utc:%Y-%m-%d %H:%M} UTC); "
                                "remove ca.pem and ca.key to make a new one")
        say(f"kept CA {ca_pem}")
    else:
        ca, ca_key = _make_ca(ca_days or max(365, days))
        _write(ca_key_p, _key_bytes(ca_key), 0o600)
        _write(ca_pem, ca.public_bytes(serialization.Encoding.PEM), 0o644)
        say(f"made CA {ca_pem}")
    out: dict[str, tuple[Path, Path]] = {}
    for n in dict.fromkeys(names):
        cert_p, key_p = _paths(d, n)
        if _leaf_ok(n, cert_p, key_p, ca, want[n]):
            os.chmod(key_p, 0o600)
            say(f"kept {n} {cert_p}")
        else:
            cert, key = _make_leaf(n, ca, ca_key, days, want[n])
            _write(key_p, _key_bytes(key), 0o600)
            _write(cert_p, cert.public_bytes(serialization.Encoding.PEM), 0o644)
            say(f"made {n} {cert_p}")
        out[n] = (cert_p, key_p)
    from .sign import make_keys
    make_keys(d, list(out))
    return out


def names_for(sc, units: list[str] | None = None, consoles: bool = False) -> list[str]:
    """The identities of a scenario's mesh: ea.<unit> for each unit (default: every unit
    that gets an EA peer), observer, console and tak (the Cursor-on-Target gateway),
    source.cp.<U> for each command post and source.fusion.<group> for each fusion group (live
    sources); with `consoles`, console.<unit> for each unit too (a commander's console)."""
    from saim_mesh.scenario import mesh_units
    units = list(units) if units is not None else mesh_units(sc)
    unknown = [u for u in units if u not in sc.taskorg.units]
    if unknown:
        raise SecurityError(f"units not in the scenario's task organization: {', '.join(unknown)}")
    groups = sorted(sc.meta.get("fusion", {}).get("groups", {}))
    from .acl import source_names
    return [*(f"ea.{u}" for u in units), "observer", "console", "tak",
            *(f"console.{u}" for u in units if consoles),
            *(f"source.{n}" for n in source_names(units, sc.taskorg, groups))]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="make-certs", description="Make the mesh's CA and one certificate per "
                                 "role (ea.<unit>, observer, console, tak, source.<name>).")
    ap.add_argument("scenario", help="scenario folder")
    ap.add_argument("out_dir", help="where ca.pem/ca.key and NAME.pem/NAME.key go")
    ap.add_argument("--units", nargs="+", help="units that get an EA identity (default: every mesh unit)")
    ap.add_argument("--days", type=int, default=30, help="validity of the leaf certificates (default 30)")
    ap.add_argument("--no-consoles", action="store_true", help="no console.<unit> identities")
    a = ap.parse_args(argv)
    from saim_mesh import scenario as S
    try:
        sc = S.load(a.scenario, events=False)
        made = make_pki(a.out_dir, names_for(sc, a.units, consoles=not a.no_consoles), a.days, echo=print)
    except (SecurityError, S.ScenarioError) as e:
        print(f"make-certs: {e}", file=sys.stderr)
        return 2
    print(f"{len(made)} identities in {Path(a.out_dir).resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
