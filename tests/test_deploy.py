"""The deployment file (issue 32 items 1-3), without starting a mesh: `deploy init`
derives a host per command post; `deploy --check` says what is wrong with a bad file in
one line each (exit 2) and never shows a traceback; `certs --deploy` puts each host's
addresses and names in its processes' certificates."""
from __future__ import annotations

import ipaddress
import tomllib
from pathlib import Path

import pytest
from cryptography import x509

from saim_mesh import cli
from saim_mesh.deploy import init
from saim_mesh.deploy.check import load
from saim_mesh.deploy.launch import plan

from .conftest import SMALL

BASE = f'''scenario = "{SMALL}"
secure = false

[[host]]
name = "BN"
addresses = ["198.18.0.1"]
eas = ["BN", "M"]
sources = ["cp.BN", "cp.BNHQ", "cp.M"]

[[host]]
name = "A"
addresses = ["198.18.0.2"]
eas = ["A", "A1", "A2", "A3", "R"]
sources = ["cp.A", "cp.B", "cp.C"]

[[router]]
name = "r-BN"
host = "BN"
cp = "BN"

[[router]]
name = "r-A"
host = "A"
cp = "A"
links = ["r-BN"]
'''


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "deploy.toml"
    p.write_text(text)
    return p


def check(tmp_path: Path, text: str, *extra: str, capsys) -> tuple[int, list[str]]:
    rc = cli.main(["deploy", str(write(tmp_path, text)), "--check", *extra])
    out = capsys.readouterr()
    assert "Traceback" not in out.out + out.err
    return rc, [x for x in out.out.splitlines() if x.strip()]


def test_init_derives_a_host_per_command_post_with_its_units_sources_and_router(tmp_path, small, capsys):
    out = tmp_path / "d.toml"
    assert cli.main(["deploy", "init", str(SMALL), "--out", str(out), "--addresses", "198.18.0.0/24"]) == 0
    capsys.readouterr()
    doc = tomllib.loads(out.read_text())
    hosts = {h["name"]: h for h in doc["host"]}
    assert list(hosts) == ["BN", "A", "B", "C"]   # the battalion's post and its three companies'
    assert hosts["BN"]["addresses"] == ["198.18.0.1"] and hosts["C"]["addresses"] == ["198.18.0.4"]
    assert hosts["A"]["eas"] == ["A", "A1", "A2", "A3", "R"] and "M" in hosts["BN"]["eas"]
    assert sorted(u for h in hosts.values() for u in h["eas"]) == sorted(
        __import__("saim_mesh.scenario", fromlist=["x"]).mesh_units(small))
    assert hosts["A"]["sources"] == ["cp.A"] and set(hosts["BN"]["sources"]) == {"cp.BN", "cp.BNHQ", "cp.M"}
    routers = {r["name"]: r for r in doc["router"]}
    assert routers["r-A"] == {"name": "r-A", "host": "A", "cp": "A", "port": 7447, "links": ["r-BN"]}
    assert routers["r-BN"]["links"] == []
    assert (tmp_path / doc["scenario"]).resolve() == SMALL.resolve()   # relative to the file
    rc, lines = check(tmp_path, out.read_text().replace(f'"{doc["scenario"]}"', f'"{SMALL}"'), capsys=capsys)
    assert rc == 0 and "OK: 4 hosts, 4 routers, 15 EA peers, 6 sources" in lines[0], lines


def test_init_on_one_address_gives_each_host_its_own_ports(small):
    dep = init.derive(small, str(SMALL), addresses="127.0.0.1")
    assert [r.port for r in dep.routers.values()] == [7447, 7448, 7449, 7450]
    assert len({c.port for h in dep.hosts.values() for c in h.consoles}) == 4
    with pytest.raises(ValueError, match="room for 2 hosts, 4 needed"):
        init.derive(small, str(SMALL), addresses="198.18.0.0/30")


def test_a_good_file_checks_and_plans_endpoints_on_the_hosts_addresses(tmp_path, capsys):
    rc, lines = check(tmp_path, BASE, capsys=capsys)
    assert rc == 0 and lines[0].endswith("OK: 2 hosts, 2 routers, 7 EA peers, 6 sources; insecure"), lines
    dep, sc = load(tmp_path / "deploy.toml")
    pl = plan(dep, "A")
    assert pl.listen == {"r-A": ["tcp/198.18.0.2:7447"]}
    assert pl.endpoints == {"r-A": "tcp/198.18.0.2:7447", "r-BN": "tcp/198.18.0.1:7447"}
    assert dep.attach("A", "A2", sc.taskorg) == "r-A" and dep.attach("BN", "M", sc.taskorg) == "r-BN"
    assert dep.attach("A", "BN", sc.taskorg) == "r-A"   # a host's processes use its own router


BAD = [   # (what the file says, the one line expected)
    ("scenario = ", "not valid TOML"),
    (BASE.replace('secure = false', 'secure = false\nspeed = nan'), "speed ('max' or a factor): expected a finite "
                                                                    "number"),
    (BASE.replace('secure = false', 'secure = false\nuntil = inf'), "until: expected a finite number >= 0"),
    (BASE.replace('cp = "A"', 'cp = "A"\nport = 7447.5'), "router #2 'r-A': port: expected a whole port number"),
    (BASE.replace('cp = "A"', 'cp = "A"\nport = 70000'), "port 70000 out of range"),
    (BASE.replace('secure = false', 'secure = false\ncolour = "red"'), "top level: unknown keys 'colour'"),
    (BASE.replace('eas = ["BN", "M"]', 'eas = ["BN", "M"]\nram = 4'), "host #1 'BN': unknown keys 'ram'"),
    (BASE.replace('"A1", "A2"', '"A1", "Z9"'), "host 'A': eas: 'Z9' is not a unit of"),
    (BASE.replace('"A1", "A2"', '"A1", "M"'), "host 'A': eas: M runs on two hosts (BN and A)"),
    (BASE.replace('"A1", "A2"', '"A1", "A1S1"'), "'A1S1' is not a unit that runs an EA peer"),
    (BASE.replace('"cp.B", ', ''), "source cp.B runs on no host"),
    (BASE.replace('"cp.B", ', '"cp.B", "cp.X", '), "host 'A': sources: 'cp.X' is not a command post's or a fusion node's source"),
    (BASE.replace('links = ["r-BN"]', 'links = ["r-XX"]'), "router 'r-A': links to 'r-XX': no such router"),
    (BASE.replace('host = "A"', 'host = "Q"'), "router 'r-A': host 'Q' is not a host of this file"),
    (BASE.replace('cp = "A"', 'cp = "Q"'), "router 'r-A': cp 'Q' is not a unit of"),
    (BASE.replace('links = ["r-BN"]', 'links = ["r-A"]'), "router 'r-A': links to itself"),
    (BASE.replace('cp = "BN"\n', 'cp = "BN"\nlinks = ["r-A"]\n'), "routers r-BN and r-A are linked twice"),
    (BASE.replace('"198.18.0.2"', '"198.18.0.300"'), "addresses: '198.18.0.300' is not an IP address"),
    (BASE.replace('addresses = ["198.18.0.2"]', ''), "host #2 'A': give its addresses"),
    (BASE.replace('"198.18.0.2"', '"198.18.0.1"').replace('host = "A"', 'host = "A"\nport = 7447'),
     "listens on 198.18.0.1 port 7447 like router r-BN"),
    (BASE.replace('secure = false', 'secure = true'), "skip"),   # addresses given: fine
    (BASE.replace('name = "A"\n', 'name = "BN"\n'), "host #2 'BN': host 'BN' named twice"),
    (BASE.replace('eas = ["BN", "M"]', 'eas = ["BN", "M"]\nfusion = ["F"]'), "no such fusion group"),
    (BASE.replace('eas = ["BN", "M"]', 'eas = ["BN", "M"]\nconsoles = [{unit = "BN", port = 8470}, '
                                       '{unit = "M", port = 8470}]'), "console M: port 8470 used twice"),
    (BASE.replace('eas = ["BN", "M"]', 'eas = ["BN", "M"]\nattach = "r-Z"'), "attach: 'r-Z' is not a router"),
    (BASE.replace(f'"{SMALL}"', '"/nonexistent/scenario"'), "scenario /nonexistent/scenario: cannot load it"),
    ("secure = true\n", "scenario: missing"),
    (BASE.replace('secure = false', 'secure = false\nlive = true'), "live = true needs start"),
    (BASE.replace('secure = false', 'secure = false\nstart = "yesterday"'), "start: 'yesterday' is not an ISO 8601"),
    (BASE.replace('secure = false', 'secure = false\ncatch_up_kbit = 0'), "catch_up_kbit: a pace must be > 0"),
    (BASE.replace('secure = false', 'secure = false\ncatch_up_kbit = "fast"'), "catch_up_kbit: expected a number"),
]


@pytest.mark.parametrize("text,says", BAD, ids=[s[:40] for _, s in BAD])
def test_a_bad_deployment_file_is_one_line_naming_what_is_wrong(tmp_path, capsys, text, says):
    rc, lines = check(tmp_path, text, capsys=capsys)
    if says == "skip":
        assert rc == 0, lines
        return
    assert rc == 2, lines
    assert any(says in x for x in lines), lines
    assert all(x.startswith(str(tmp_path)) for x in lines), lines   # each line names the file


def test_check_for_a_host_says_when_an_address_is_not_this_machines(tmp_path, capsys):
    rc, lines = check(tmp_path, BASE, "--host", "A", capsys=capsys)
    assert rc == 2 and lines == [f"{tmp_path / 'deploy.toml'}: host 'A': address 198.18.0.2 is not one of this "
                                 "machine's (is this A?)"], lines
    rc, lines = check(tmp_path, BASE.replace("198.18.0.2", "127.0.0.1"), "--host", "A", capsys=capsys)
    assert rc == 0, lines
    rc, lines = check(tmp_path, BASE, "--host", "Z", capsys=capsys)
    assert rc == 2 and "--host Z: not a host of this file (A, BN)" in lines[0]
    rc, lines = check(tmp_path, BASE.replace('addresses = ["198.18.0.2"]', 'interface = "nosuch0"'), "--host", "A",
                      capsys=capsys)
    assert rc == 2 and "interface 'nosuch0' does not exist on this machine" in lines[0], lines


def test_several_problems_are_each_said(tmp_path, capsys):
    text = BASE.replace('"A1", "A2"', '"A1", "Z9"').replace('links = ["r-BN"]', 'links = ["r-XX"]')
    rc, lines = check(tmp_path, text, capsys=capsys)
    assert rc == 2 and len(lines) == 2, lines


def test_an_unreadable_file_and_a_missing_one_are_one_line(tmp_path, capsys):
    p = tmp_path / "bin.toml"
    p.write_bytes(b"\xff\xfe\x00junk")
    assert cli.main(["deploy", str(p), "--check"]) == 2
    assert cli.main(["deploy", str(tmp_path / "none.toml"), "--check"]) == 2
    out = capsys.readouterr().out.splitlines()
    assert out == [f"{p}: not a text file (UTF-8)", f"{tmp_path / 'none.toml'}: cannot read the deployment file "
                   "(No such file or directory)"]


def _sans(path: Path) -> set[str]:
    cert = x509.load_pem_x509_certificate(path.read_bytes())
    ext = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    return {str(a) for a in ext.get_values_for_type(x509.IPAddress)} | set(ext.get_values_for_type(x509.DNSName))


def test_certs_for_a_deployment_carry_each_hosts_addresses_and_names(tmp_path, capsys):
    text = BASE.replace("secure = false", "secure = true").replace(
        'addresses = ["198.18.0.2"]', 'addresses = ["198.18.0.2", "2001:db8::2"]\nnames = ["coa.example"]')
    f = write(tmp_path, text)
    assert cli.main(["certs", "--deploy", str(f)]) == 0
    pki = tmp_path / "pki"
    assert _sans(pki / "router.r-A.pem") == {"127.0.0.1", "localhost", "198.18.0.2", "2001:db8::2", "coa.example"}
    assert _sans(pki / "ea.A2.pem") == _sans(pki / "source.cp.B.pem") == _sans(pki / "router.r-A.pem")
    assert _sans(pki / "router.r-BN.pem") == _sans(pki / "ea.BN.pem") == {"127.0.0.1", "localhost", "198.18.0.1"}
    assert _sans(pki / "observer.pem") == {"127.0.0.1", "localhost"}   # runs on no host
    cn = x509.load_pem_x509_certificate((pki / "ea.A2.pem").read_bytes()).subject.rfc4514_string()
    assert cn == "CN=ea.A2"   # identity rules unchanged
    before = (pki / "ea.BN.pem").read_bytes(), (pki / "ea.A2.pem").read_bytes()
    f.write_text(text.replace("198.18.0.2", "198.18.0.9"))   # A moved: its certificates are made again
    assert cli.main(["certs", "--deploy", str(f)]) == 0
    assert (pki / "ea.BN.pem").read_bytes() == before[0] and (pki / "ea.A2.pem").read_bytes() != before[1]
    assert "198.18.0.9" in _sans(pki / "ea.A2.pem")
    capsys.readouterr()


def test_a_secure_host_without_its_certificates_is_one_line(tmp_path, capsys):
    f = write(tmp_path, BASE.replace("secure = false", "secure = true").replace("198.18.0.2", "127.0.0.1"))
    rc = cli.main(["deploy", str(f), "--host", "A", "--out-dir", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "saim-mesh certs --deploy FILE" in err and "file missing" in err


def test_the_example_deployment_checks(capsys):
    f = SMALL.parents[1] / "configs" / "deploy-battalion.toml"
    assert cli.main(["deploy", str(f), "--check"]) == 0, capsys.readouterr()
    dep, _ = load(f)
    assert all(ipaddress.ip_address(h.addresses[0]) in ipaddress.ip_network("198.18.0.0/15")
               for h in dep.hosts.values())


def test_check_for_a_host_says_when_a_routers_port_is_taken(tmp_path, capsys):
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        text = BASE.replace("198.18.0.2", "127.0.0.1").replace('cp = "A"', f'cp = "A"\nport = {port}')
        rc, lines = check(tmp_path, text, "--host", "A", capsys=capsys)
    assert rc == 2 and lines == [f"{tmp_path / 'deploy.toml'}: router 'r-A': port {port} on 127.0.0.1 is in use "
                                 "(is this host's mesh running already?)"], lines


def test_a_host_without_a_router_attaches_to_its_command_posts_and_an_interface_gives_addresses(tmp_path, capsys):
    text = BASE.replace('"A1", "A2", "A3", "R"', '"A1", "A3", "R"') + '''
[[host]]
name = "vehicle"
interface = "lo"
eas = ["A2"]
'''
    rc, lines = check(tmp_path, text, "--host", "vehicle", capsys=capsys)
    assert rc == 0, lines
    dep, sc = load(tmp_path / "deploy.toml")
    assert dep.attach("vehicle", "A2", sc.taskorg) == "r-A"   # its company's router, on host A
    pl = plan(dep, "vehicle")
    assert pl.listen == {} and pl.endpoints["r-A"] == "tcp/198.18.0.2:7447"
    moved = text.replace('host = "A"', 'host = "vehicle"')   # r-A on the vehicle, which has no address
    rc, lines = check(tmp_path, moved, capsys=capsys)
    assert rc == 2 and lines == [f"{tmp_path / 'deploy.toml'}: host 'A': A attaches to r-A on host vehicle, which "
                                 "has no address"], lines
    rc, lines = check(tmp_path, moved.replace('links = ["r-BN"]', 'links = []').replace(
        'cp = "BN"\n', 'cp = "BN"\nlinks = ["r-A"]\n'), capsys=capsys)
    assert rc == 2 and any("router 'r-BN': links to r-A on host vehicle, which has no address" in x for x in lines), \
        lines


def test_starting_a_host_from_a_bad_file_says_each_problem_and_starts_nothing(tmp_path, capsys):
    text = BASE.replace('"A1", "A2"', '"A1", "Z9"').replace('links = ["r-BN"]', 'links = ["r-XX"]')
    rc = cli.main(["deploy", str(write(tmp_path, text)), "--host", "A", "--out-dir", str(tmp_path / "out")])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 3 and not (tmp_path / "out").exists(), err   # the two, and A's address
    assert "Traceback" not in " ".join(err)
