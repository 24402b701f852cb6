"""DDS transport settings without rclpy: the local and network environments, generated profiles, input
validation, `lightfast dds env`, and the one-line description each node logs."""
from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from lightfast import cli
from lightfast.errors import LightfastError
from lightfast.ros import transport
from lightfast.ros.transport import (
    NETWORK_PROFILE_PATH,
    PROFILE_PATH,
    apply_env,
    describe_profile,
    describe_transport,
    local_transport_env,
    network_profile_xml,
    network_transport_env,
    shell_lines,
    use_local_transport,
)

LOCAL_LINE = ("DDS: profile local (lightfast/ros/fastdds_local.xml: shared memory 64 MB + UDP on loopback only), "
              "discovery LOCALHOST, domain 0; for several machines see 'lightfast dds env --network'")
NETWORK_SUMMARY = "lightfast/ros/fastdds_network.xml: shared memory 64 MB + UDPv4 on all interfaces"


@pytest.fixture
def empty_cwd(tmp_path: Path) -> Path:
    """A working directory without DEFAULT_FASTRTPS_PROFILES.xml (Fast DDS would load one from there)."""
    path = tmp_path / "cwd"
    path.mkdir()
    return path


# --- describe_transport ----------------------------------------------------------------------------------------

def test_local_transport_is_described_with_the_way_out(empty_cwd: Path) -> None:
    assert describe_transport(local_transport_env(), cwd=empty_cwd) == LOCAL_LINE
    env = {**local_transport_env(), "ROS_DOMAIN_ID": "17"}
    assert ", domain 17;" in describe_transport(env, cwd=empty_cwd)
    assert ", domain 42;" in describe_transport(env, domain_id=42, cwd=empty_cwd)


def test_network_transport_is_described(empty_cwd: Path, tmp_path: Path) -> None:
    env = network_transport_env(domain_id=5)
    assert describe_transport(env, cwd=empty_cwd) == (
        f"DDS: profile network ({NETWORK_SUMMARY}), discovery SUBNET, domain 5")
    env = network_transport_env(["192.0.2.1", "robot-b.local"])
    assert describe_transport(env, cwd=empty_cwd) == (
        f"DDS: profile network ({NETWORK_SUMMARY}), discovery SUBNET + static peers 192.0.2.1, robot-b.local, domain 0")
    env = network_transport_env((), ["192.0.2.1"], udp_only=True, cache_dir=tmp_path / "cache")
    line = describe_transport(env, cwd=empty_cwd)
    assert line.startswith(f"DDS: profile network (generated {tmp_path / 'cache'}/fastdds_network-")
    assert line.endswith(": UDPv4 on 192.0.2.1, 127.0.0.1), discovery SUBNET, domain 0")


def test_user_profiles_are_described_from_their_xml(tmp_path: Path, empty_cwd: Path) -> None:
    mine = tmp_path / "robot.xml"
    mine.write_text(network_profile_xml(["eth0"]).replace("67108864", "8388608"))
    env = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(mine), "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    assert describe_transport(env, cwd=empty_cwd) == (
        f"DDS: user profile {mine} (shared memory 8 MB + UDPv4 on eth0, 127.0.0.1), discovery SUBNET, domain 0")
    builtin = tmp_path / "builtin.xml"
    builtin.write_text('<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"><participant '
                       'profile_name="p" is_default_profile="true"><rtps/></participant></profiles>')
    assert describe_profile(builtin) == "built-in shared memory 512 KB + UDPv4 on all interfaces"
    assert describe_profile(tmp_path / "nope.xml").startswith("missing: Fast DDS built-in")
    (tmp_path / "bad.xml").write_text("<profiles><!-- a -- b --></profiles>")
    assert describe_profile(tmp_path / "bad.xml").startswith("unreadable (ParseError): Fast DDS built-in")


def test_default_xml_in_the_working_directory_is_mentioned(tmp_path: Path, empty_cwd: Path) -> None:
    (empty_cwd / "DEFAULT_FASTRTPS_PROFILES.xml").write_text(network_profile_xml(udp_only=True))
    line = describe_transport(local_transport_env(), cwd=empty_cwd)
    assert f"and {empty_cwd}/DEFAULT_FASTRTPS_PROFILES.xml from the working directory (UDPv4 on all interfaces)" \
        in line
    skip = {**local_transport_env(), "SKIP_DEFAULT_XML_FILE": "1"}
    assert describe_transport(skip, cwd=empty_cwd) == LOCAL_LINE


@pytest.mark.parametrize(("env", "expected"), [
    ({}, "DDS: no profile (Fast DDS built-in shared memory 512 KB + UDPv4 on all interfaces), discovery SUBNET "
         f"({transport.RANGE_ENV} unset), domain 0"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "subnet"}, "discovery LOCALHOST (unknown ROS_AUTOMATIC_DISCOVERY_RANGE="
                                                  "'subnet'), domain 0; for several machines"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF", "ROS_STATIC_PEERS": "192.0.2.1"},
     "discovery OFF (ROS_STATIC_PEERS ignored), domain 0; for several machines"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "192.0.2.1", "ROS_LOCALHOST_ONLY": "1"},
     "discovery LOCALHOST (ROS_LOCALHOST_ONLY=1, deprecated, overrides ROS_AUTOMATIC_DISCOVERY_RANGE and "
     "ROS_STATIC_PEERS), domain 0"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_STATIC_PEERS": "192.0.2.1;192.0.2.2"},
     "discovery LOCALHOST + static peers 192.0.2.1, 192.0.2.2 (rmw_fastrtps sends discovery to the peers over a "
     "UDP transport of its own, past any whitelist), domain 0"),
    ({"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"},
     "DDS: rmw_cyclonedds_cpp (Fast DDS profiles do not apply), discovery SUBNET, domain 0"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_DISCOVERY_SERVER": "192.0.2.9:11811"},
     "discovery SUBNET, discovery server 192.0.2.9:11811, domain 0"),
])
def test_discovery_is_described_as_rcl_applies_it(env: dict[str, str], expected: str, empty_cwd: Path) -> None:
    assert expected in describe_transport(env, cwd=empty_cwd)


def test_describe_transport_reads_the_process_environment_by_default(monkeypatch: pytest.MonkeyPatch,
                                                                     empty_cwd: Path) -> None:
    for key, value in network_transport_env(["192.0.2.7"]).items():
        monkeypatch.setenv(key, value)
    for key in ("ROS_LOCALHOST_ONLY", "ROS_DOMAIN_ID", "ROS_DISCOVERY_SERVER", "SKIP_DEFAULT_XML_FILE"):
        monkeypatch.delenv(key, raising=False)
    monkeypatch.chdir(empty_cwd)
    assert describe_transport() == (f"DDS: profile network ({NETWORK_SUMMARY}), discovery SUBNET + static peers "
                                    "192.0.2.7, domain 0")


# --- use_local_transport, network_transport_env ----------------------------------------------------------------

def test_use_local_transport_keeps_what_the_user_exported(monkeypatch: pytest.MonkeyPatch) -> None:
    for key, value in network_transport_env(["192.0.2.1"]).items():
        monkeypatch.setenv(key, value)
    use_local_transport()
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(NETWORK_PROFILE_PATH)
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert os.environ["ROS_STATIC_PEERS"] == "192.0.2.1"
    monkeypatch.delenv("FASTRTPS_DEFAULT_PROFILES_FILE")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "")
    use_local_transport()
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(PROFILE_PATH)
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"


def test_network_env_always_sets_the_range_and_dedups_peers(tmp_path: Path) -> None:
    env = network_transport_env(["192.0.2.2", "192.0.2.1", "192.0.2.2"], domain_id=9)
    assert env == {"FASTRTPS_DEFAULT_PROFILES_FILE": str(NETWORK_PROFILE_PATH),
                   "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "192.0.2.2;192.0.2.1",
                   "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp", "ROS_DOMAIN_ID": "9"}
    assert "ROS_STATIC_PEERS" not in network_transport_env()


def test_generated_profile_is_written_once_atomically(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    env = network_transport_env((), ["192.0.2.1", "eth0"])
    path = Path(env["FASTRTPS_DEFAULT_PROFILES_FILE"])
    assert path.parent == tmp_path / "xdg" / "lightfast" / "dds"
    assert describe_profile(path) == "shared memory 64 MB + UDPv4 on 192.0.2.1, eth0, 127.0.0.1"
    mtime = path.stat().st_mtime_ns
    assert network_transport_env((), ["192.0.2.1", "eth0"]) == env  # same content, same file, not rewritten
    assert path.stat().st_mtime_ns == mtime
    other = Path(network_transport_env((), ["192.0.2.1"], udp_only=True)["FASTRTPS_DEFAULT_PROFILES_FILE"])
    assert other != path and describe_profile(other) == "UDPv4 on 192.0.2.1, 127.0.0.1"
    assert sorted(p.name for p in path.parent.iterdir()) == sorted([path.name, other.name])  # no temp files left
    tree = ET.parse(path)  # well-formed (an XML comment must not contain "--")
    ns = {"f": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    assert [e.text for e in tree.findall(".//f:interfaceWhiteList/*", ns)] == ["192.0.2.1", "eth0", "127.0.0.1"]
    assert [e.tag.split("}")[1] for e in tree.findall(".//f:interfaceWhiteList/*", ns)] == \
        ["address", "interface", "address"]


def test_packaged_network_profile_is_the_generated_one_without_options() -> None:
    ET.parse(NETWORK_PROFILE_PATH)
    ET.parse(PROFILE_PATH)
    assert describe_profile(NETWORK_PROFILE_PATH) == "shared memory 64 MB + UDPv4 on all interfaces"
    packaged = ET.tostring(ET.parse(NETWORK_PROFILE_PATH).getroot())
    generated = ET.tostring(ET.fromstring(network_profile_xml()))
    squash = b"".join  # compare the elements, not the whitespace
    assert squash(packaged.split()) == squash(generated.split())


@pytest.mark.parametrize(("hosts", "interfaces", "message"), [
    (["192.0.2.300"], [], "bad host '192.0.2.300': not an IPv4 address"),
    (["192.0.2.1:7412"], [], "no port"),
    (["fe80::1"], [], "IPv4 static peers only"),
    (["239.255.0.1"], [], "not a unicast address"),
    (["0.0.0.0"], [], "not a unicast address"),
    (["a;b"], [], "one address or name per argument"),
    (["bad_name!"], [], "not an IPv4 address or host name"),
    (["-robot"], [], "not an IPv4 address or host name"),
    ([""], [], "empty host name"),
    ([], ["192.0.2"], "bad interface address '192.0.2': not an IPv4 address"),
    ([], ["::1"], "IPv4 addresses"),
    ([], ["eth0; rm -rf"], "not an IPv4 address or interface name"),
    ([], ["averyveryverylongname"], "not an IPv4 address or interface name"),
])
def test_bad_addresses_are_refused(hosts: list[str], interfaces: list[str], message: str, tmp_path: Path) -> None:
    with pytest.raises(LightfastError, match=message.replace("(", r"\(").replace(")", r"\)")):
        network_transport_env(hosts, interfaces, cache_dir=tmp_path)
    assert not any(tmp_path.iterdir())  # nothing written for bad input


def test_shell_lines_quote_values_and_apply_env_matches_eval(tmp_path: Path) -> None:
    env = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(tmp_path / "a dir" / "p.xml"), "ROS_STATIC_PEERS": "h1;h2"}
    lines = shell_lines(env, ["ROS_LOCALHOST_ONLY", "ROS_STATIC_PEERS"])
    assert lines[-1] == "unset ROS_LOCALHOST_ONLY"  # what is exported is not also unset
    base = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "ROS_LOCALHOST_ONLY": "1", "ROS_STATIC_PEERS": "x"}
    script = "\n".join(lines) + "\nenv -0"
    out = subprocess.run(["bash", "-c", script], env=base, capture_output=True, text=True, check=True).stdout
    got = dict(item.split("=", 1) for item in out.split("\0") if item and not item.startswith(("_=", "PWD=",
                                                                                               "SHLVL=")))
    assert got == apply_env(base, env, ["ROS_LOCALHOST_ONLY"])


# --- lightfast dds env ------------------------------------------------------------------------------------------

def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_dds_env_prints_the_local_exports_by_default(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(["dds", "env"], capsys)
    assert code == 0 and err == ""
    assert out.splitlines() == [f"export FASTRTPS_DEFAULT_PROFILES_FILE={PROFILE_PATH}",
                                "export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST",
                                "export RMW_IMPLEMENTATION=rmw_fastrtps_cpp",
                                "unset ROS_STATIC_PEERS"]


def test_dds_env_network(capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    code, out, err = run_cli(["dds", "env", "--network", "--hosts", "192.0.2.1", "192.0.2.2"], capsys)
    assert code == 0 and err == ""
    assert out.splitlines() == [
        f"# DDS: profile network ({NETWORK_SUMMARY}), discovery SUBNET + static peers 192.0.2.1, 192.0.2.2, "
        "domain 0",
        f"export FASTRTPS_DEFAULT_PROFILES_FILE={NETWORK_PROFILE_PATH}",
        "export ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET",
        "export ROS_STATIC_PEERS='192.0.2.1;192.0.2.2'",
        "export RMW_IMPLEMENTATION=rmw_fastrtps_cpp",
        "unset ROS_LOCALHOST_ONLY"]
    code, out, err = run_cli(["dds", "env", "--network", "--interface", "127.0.0.1", "--udp-only"], capsys)
    assert code == 0 and err == ""  # 127.0.0.1 exists on every machine: no warning
    generated = next((tmp_path / "lightfast" / "dds").glob("fastdds_network-*.xml"))
    assert f"export FASTRTPS_DEFAULT_PROFILES_FILE={generated}" in out.splitlines()
    assert out.splitlines()[-1] == "unset ROS_LOCALHOST_ONLY ROS_STATIC_PEERS"
    assert f"(generated {generated}: UDPv4 on 127.0.0.1)" in out.splitlines()[0]
    code, out, err = run_cli(["dds", "env", "--network", "--interface", "192.0.2.254"], capsys)
    assert code == 0 and "192.0.2.254 is no interface or IPv4 address of this machine" in err


@pytest.mark.parametrize("argv", [["--network", "--hosts", "192.0.2.300"], ["--network", "--interface", "x/y"],
                                  ["--hosts", "192.0.2.1"], ["--udp-only"]])
def test_dds_env_bad_input_is_one_line_and_exit_1(argv: list[str], capsys: pytest.CaptureFixture[str],
                                                  tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    code, out, err = run_cli(["dds", "env", *argv], capsys)
    assert (code, out) == (1, "")
    assert len(err.splitlines()) == 1 and err.startswith("lightfast: error: ")


def test_dds_env_refuses_host_names_that_do_not_resolve(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    import socket

    looked_up: list[str] = []

    def fake_getaddrinfo(host: str, *_args: object) -> list:  # no real name lookup from a test
        looked_up.append(host)
        if host == "robot-b.lan":
            return [(socket.AF_INET, socket.SOCK_DGRAM, 17, "", ("192.0.2.2", 0))]
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(socket, "getaddrinfo", fake_getaddrinfo)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    code, out, err = run_cli(["dds", "env", "--network", "--hosts", "192.0.2.1", "robot-b.lan"], capsys)
    assert code == 0 and "export ROS_STATIC_PEERS='192.0.2.1;robot-b.lan'" in out.splitlines()
    code, out, err = run_cli(["dds", "env", "--network", "--hosts", "192.0.2.1", "robot-c.lan"], capsys)
    assert (code, out) == (1, "")
    assert err == ("lightfast: error: cannot resolve robot-c.lan to an IPv4 address (the nodes would not start: "
                   "rmw_fastrtps resolves ROS_STATIC_PEERS when it creates a node)\n")
    assert looked_up == ["robot-b.lan", "robot-c.lan"]  # addresses are not looked up


def test_dds_env_output_evaluates_in_a_shell(tmp_path: Path) -> None:
    """The documented use, end to end: eval in bash, with a cache path that has a space in it."""
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "my cache"), "ROS_LOCALHOST_ONLY": "1"}
    script = (f'eval "$({sys.executable} -m lightfast dds env --network --hosts 192.0.2.1 192.0.2.2 '
              '--interface 127.0.0.1)" && printf "%s|%s|%s|%s" "$FASTRTPS_DEFAULT_PROFILES_FILE" '
              '"$ROS_STATIC_PEERS" "$ROS_AUTOMATIC_DISCOVERY_RANGE" "${ROS_LOCALHOST_ONLY-unset}"')
    out = subprocess.run(["bash", "-c", script], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    profile, peers, discovery, localhost_only = out.stdout.split("|")
    assert Path(profile).is_file() and Path(profile).parent == tmp_path / "my cache" / "lightfast" / "dds"
    assert (peers, discovery, localhost_only) == ("192.0.2.1;192.0.2.2", "SUBNET", "unset")
