"""DDS transport settings: local by default, a network profile for several machines, and a truthful summary.

Every lightfast entry point (CLI, node ``main``, scripts, tests) calls :func:`use_local_transport` before rclpy
creates its first participant. It points Fast DDS at the packaged profile (64 MB shared-memory segments, UDP on
loopback only) and limits automatic discovery to this host, unless the user has set those variables already.

To run the nodes on several machines, export the variables of :func:`network_transport_env` first (the CLI prints
them: ``eval "$(lightfast dds env --network [--hosts HOST ...] [--interface ADDR ...])"``): the packaged
``fastdds_network.xml`` (or a generated variant: UDP interface whitelist, no shared memory),
``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` and optionally ``ROS_STATIC_PEERS``. :func:`describe_transport` says
in one line what a process uses.

How ROS 2 Jazzy (rcl 9.2, rmw_fastrtps 8.4, Fast DDS 2.14) reads the variables:

- ``ROS_AUTOMATIC_DISCOVERY_RANGE``: unset or empty is SUBNET; an unknown value is LOCALHOST (rcl warns).
  SUBNET leaves the profile alone (multicast discovery on 239.255.0.1). LOCALHOST stops listening on multicast,
  sends discovery to 127.0.0.1 only, and *adds* a default shared-memory and a UDPv4 transport (no whitelist) to
  the profile's. OFF: no other participant at all.
- ``ROS_STATIC_PEERS``: ``;``-separated IPv4 addresses or host names (resolved once; the first IPv4 is used, a
  name that does not resolve makes participant creation fail), ignored with OFF. Each becomes a unicast initial
  peer on the well-known ports of its first ``maxInitialPeersRange`` participants; with SUBNET the multicast
  address is added back, so multicast discovery goes on as well.
- ``ROS_LOCALHOST_ONLY=1`` (deprecated) wins over both: LOCALHOST, and the static peers are dropped.
"""
from __future__ import annotations

import hashlib
import ipaddress
import os
import re
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

from lightfast.ros.errors import TransportError

PROFILE_PATH = Path(__file__).with_name("fastdds_local.xml")
NETWORK_PROFILE_PATH = Path(__file__).with_name("fastdds_network.xml")
PROFILE_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
RANGE_ENV = "ROS_AUTOMATIC_DISCOVERY_RANGE"
PEERS_ENV = "ROS_STATIC_PEERS"
LOCALHOST_ONLY_ENV = "ROS_LOCALHOST_ONLY"
RMW_ENV = "RMW_IMPLEMENTATION"
DOMAIN_ENV = "ROS_DOMAIN_ID"
FASTRTPS_RMWS = ("rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")
GENERATED_PREFIX = "fastdds_network-"
NETWORK_HINT = "for several machines see 'lightfast dds env --network'"
_PEER_MAX_LENGTH = 255  # rmw: RMW_DISCOVERY_OPTIONS_STATIC_PEERS_MAX_LENGTH - 1; longer peers are skipped
_HOSTNAME = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")
_IFNAME = re.compile(r"[A-Za-z][A-Za-z0-9_.@-]{0,14}")  # Linux: at most 15 characters (IFNAMSIZ - 1)

#: variables that ``lightfast dds env`` unsets so that a shell holds exactly one configuration: a stale
#: ROS_STATIC_PEERS would send the local profile's discovery to other hosts; ROS_LOCALHOST_ONLY=1 would override
#: the network profile's discovery range.
LOCAL_UNSET = (PEERS_ENV,)
NETWORK_UNSET = (LOCALHOST_ONLY_ENV,)


def local_transport_env(*, discovery_range: str = "LOCALHOST", domain_id: int | None = None) -> dict[str, str]:
    """The environment variables of the local transport, e.g. to pass to a subprocess."""
    env = {PROFILE_ENV: str(PROFILE_PATH), RANGE_ENV: discovery_range, RMW_ENV: "rmw_fastrtps_cpp"}
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(int(domain_id))
    return env


def use_local_transport(*, force: bool = False) -> None:
    """Set the local transport variables in this process (``force`` overrides what the user set)."""
    for key, value in local_transport_env().items():
        if force or not os.environ.get(key):
            os.environ[key] = value


# --- network profile ------------------------------------------------------------------------------------------

def validate_peer(peer: str) -> str:
    """``peer`` as ROS_STATIC_PEERS takes it (an IPv4 address or a host name), or a :class:`TransportError`."""
    text = peer.strip()
    if not text:
        raise TransportError("empty host name")
    if ";" in text or any(c.isspace() for c in text):
        raise TransportError(f"bad host {peer!r}: give one address or name per argument")
    if re.fullmatch(r"[0-9.]+", text):
        return str(_ipv4(text, what="host"))
    if ":" in text:
        if _is_ipv6(text):
            raise TransportError(f"bad host {peer!r}: rmw_fastrtps (Jazzy) takes IPv4 static peers only")
        raise TransportError(f"bad host {peer!r}: no port (Fast DDS tries the well-known ports 7410+ of each peer)")
    name = text.rstrip(".")
    if len(name) > min(253, _PEER_MAX_LENGTH) or not all(_HOSTNAME.fullmatch(label) for label in name.split(".")):
        raise TransportError(f"bad host {peer!r}: not an IPv4 address or host name")
    return text


def validate_interface(interface: str) -> str:
    """``interface`` for a Fast DDS interface whitelist: an IPv4 address of this machine or an interface name."""
    text = interface.strip()
    if re.fullmatch(r"[0-9.]+", text):
        return str(_ipv4(text, what="interface address"))
    if _is_ipv6(text):
        raise TransportError(f"bad interface {interface!r}: the UDPv4 transport takes IPv4 addresses")
    if not _IFNAME.fullmatch(text):
        raise TransportError(f"bad interface {interface!r}: not an IPv4 address or interface name (e.g. eth0)")
    return text


def _ipv4(text: str, *, what: str) -> ipaddress.IPv4Address:
    try:
        address = ipaddress.IPv4Address(text)
    except ValueError:
        raise TransportError(f"bad {what} {text!r}: not an IPv4 address") from None
    if address.is_unspecified or address.is_multicast or address == ipaddress.IPv4Address("255.255.255.255"):
        raise TransportError(f"bad {what} {text!r}: not a unicast address")
    return address


def _is_ipv6(text: str) -> bool:
    try:
        ipaddress.IPv6Address(text.split("%")[0])
    except ValueError:
        return False
    return True


def _unique(items: Iterable[str]) -> list[str]:
    return list(dict.fromkeys(items))


def network_profile_xml(interfaces: Sequence[str] = (), *, udp_only: bool = False) -> str:
    """The network profile's XML: shared memory (unless ``udp_only``) and UDPv4 on ``interfaces`` (all if empty;
    127.0.0.1 is always added to a whitelist so that processes on one machine still reach each other by UDP)."""
    whitelist = _unique([*interfaces, "127.0.0.1"]) if interfaces else []
    tags = ["address" if re.fullmatch(r"[0-9.]+", a) else "interface" for a in whitelist]
    entries = "".join(f"\n          <{tag}>{a}</{tag}>" for tag, a in zip(tags, whitelist, strict=True))
    udp_whitelist = f"\n        <interfaceWhiteList>{entries}\n        </interfaceWhiteList>" if whitelist else ""
    shm_descriptor = ("" if udp_only else """
      <transport_descriptor>
        <transport_id>shm_big</transport_id>
        <type>SHM</type>
        <segment_size>67108864</segment_size>
      </transport_descriptor>""")
    shm_ref = "" if udp_only else "\n          <transport_id>shm_big</transport_id>"
    what = ("UDPv4 only (no shared memory)" if udp_only else "shared memory 64 MB + UDPv4") + (
        " on " + ", ".join(whitelist) if whitelist else " on all interfaces")
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<!-- generated by lightfast dds env (network): {what}; discovery comes from the environment -->
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>{shm_descriptor}
      <transport_descriptor>
        <transport_id>udp_net</transport_id>
        <type>UDPv4</type>
        <maxInitialPeersRange>32</maxInitialPeersRange>
        <sendBufferSize>4194304</sendBufferSize>
        <receiveBufferSize>4194304</receiveBufferSize>{udp_whitelist}
      </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="lightfast_network" is_default_profile="true">
    <rtps>
      <userTransports>{shm_ref}
          <transport_id>udp_net</transport_id>
      </userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
</profiles>
"""


def profile_cache_dir() -> Path:
    """Where generated profiles go: ``$XDG_CACHE_HOME/lightfast/dds`` (default ``~/.cache/lightfast/dds``)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "lightfast" / "dds"


def write_network_profile(interfaces: Sequence[str] = (), *, udp_only: bool = False,
                          cache_dir: Path | None = None) -> Path:
    """Write the generated network profile atomically (named by its content, so it is written once) and return
    its path."""
    text = network_profile_xml(interfaces, udp_only=udp_only)
    folder = Path(cache_dir) if cache_dir is not None else profile_cache_dir()
    path = folder / f"{GENERATED_PREFIX}{hashlib.sha1(text.encode()).hexdigest()[:12]}.xml"
    if path.is_file() and path.read_text() == text:
        return path
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".profile-", suffix=".xml")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def network_transport_env(hosts: Sequence[str] = (), interfaces: Sequence[str] = (), *, udp_only: bool = False,
                          domain_id: int | None = None, cache_dir: Path | None = None) -> dict[str, str]:
    """The environment variables of the network transport (validated; raises :class:`TransportError`).

    ``hosts``: ROS_STATIC_PEERS (unicast discovery of these machines, besides SUBNET's multicast); ``interfaces``:
    a UDP whitelist (IPv4 addresses or interface names) and ``udp_only`` (no shared memory, e.g. for containers
    that do not share /dev/shm) need a generated profile, written to ``cache_dir`` (default
    :func:`profile_cache_dir`); otherwise the packaged ``fastdds_network.xml`` is used. The discovery range is
    always exported (SUBNET): an unset one would become LOCALHOST through :func:`use_local_transport`."""
    peers = _unique(validate_peer(h) for h in hosts)
    allowed = _unique(validate_interface(i) for i in interfaces)
    if len(";".join(peers)) > 4096:
        raise TransportError("too many static peers")
    if allowed or udp_only:
        profile = write_network_profile(allowed, udp_only=udp_only, cache_dir=cache_dir)
    else:
        profile = NETWORK_PROFILE_PATH
    env = {PROFILE_ENV: str(profile), RANGE_ENV: "SUBNET"}
    if peers:
        env[PEERS_ENV] = ";".join(peers)
    env[RMW_ENV] = "rmw_fastrtps_cpp"
    if domain_id is not None:
        env[DOMAIN_ENV] = str(int(domain_id))
    return env


def unresolved_hosts(hosts: Sequence[str]) -> list[str]:
    """The host names among ``hosts`` that do not resolve to an IPv4 address here (rmw_fastrtps resolves each
    static peer when a node starts, and a node with one it cannot resolve fails: "Unable to resolve peer").
    Addresses are not looked up; names go to the system resolver (/etc/hosts, DNS)."""
    import socket

    missing = []
    for host in hosts:
        if re.fullmatch(r"[0-9.]+", host):
            continue
        try:
            socket.getaddrinfo(host, None, socket.AF_INET)
        except (OSError, UnicodeError):
            missing.append(host)
    return missing


def local_ipv4_interfaces() -> dict[str, str]:
    """This machine's interfaces with an IPv4 address: {name: primary address} (Linux; empty elsewhere)."""
    import fcntl
    import socket
    import struct

    found: dict[str, str] = {}
    try:
        names = [name for _, name in socket.if_nameindex()]
    except OSError:
        return found
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for name in names:
            try:
                raw = fcntl.ioctl(s.fileno(), 0x8915, struct.pack("256s", name[:15].encode()))  # SIOCGIFADDR
            except OSError:
                continue
            found[name] = socket.inet_ntoa(raw[20:24])
    return found


def unknown_interfaces(interfaces: Sequence[str]) -> list[str]:
    """The entries of ``interfaces`` that name no interface or address of this machine (Fast DDS falls back to
    loopback when nothing in a whitelist exists)."""
    local = local_ipv4_interfaces()
    if not local:
        return []
    known = set(local) | set(local.values())
    return [i for i in interfaces if i not in known]


def shell_lines(env: Mapping[str, str], unset: Iterable[str] = ()) -> list[str]:
    """``export`` lines for ``env`` and ``unset`` lines, quoted for ``eval``."""
    import shlex

    lines = [f"export {key}={shlex.quote(value)}" for key, value in env.items()]
    names = [name for name in unset if name not in env]
    if names:
        lines.append("unset " + " ".join(names))
    return lines


def apply_env(base: Mapping[str, str], env: Mapping[str, str], unset: Iterable[str] = ()) -> dict[str, str]:
    """``base`` after ``eval`` of :func:`shell_lines` (``env``, ``unset``): e.g. a child process's environment."""
    drop = set(unset)
    result = {k: v for k, v in base.items() if k not in drop}
    result.update(env)
    return result


# --- what a process uses --------------------------------------------------------------------------------------

def describe_profile(path: Path) -> str:
    """The transports of a Fast DDS XML file's default participant profile, e.g. ``shared memory 64 MB + UDPv4 on
    127.0.0.1`` (what Fast DDS 2.14 does with it: a missing or unreadable file leaves its built-in transports)."""
    builtin = "Fast DDS built-in shared memory 512 KB + UDPv4 on all interfaces"
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        return f"missing: {builtin}"
    except (OSError, ET.ParseError) as exc:
        return f"unreadable ({type(exc).__name__}): {builtin}"

    def local(tag: str) -> str:
        return tag.rsplit("}", 1)[-1]

    def child(elem: ET.Element, name: str) -> ET.Element | None:
        return next((c for c in elem if local(c.tag) == name), None)

    descriptors = {}
    for elem in root.iter():
        if local(elem.tag) == "transport_descriptor":
            tid = child(elem, "transport_id")
            if tid is not None and tid.text:
                descriptors[tid.text.strip()] = elem
    participant = next((e for e in root.iter() if local(e.tag) == "participant"
                        and e.get("is_default_profile", "").lower() == "true"), None)
    if participant is None:
        return f"no default participant profile: {builtin}"
    rtps = child(participant, "rtps")
    user = child(rtps, "userTransports") if rtps is not None else None
    use_builtin = child(rtps, "useBuiltinTransports") if rtps is not None else None
    parts = []
    for transport_id in ([] if user is None else [c.text.strip() for c in user if c.text]):
        desc = descriptors.get(transport_id)
        parts.append(_describe_descriptor(desc, child, local) if desc is not None else f"{transport_id} (undefined)")
    if use_builtin is None or (use_builtin.text or "").strip().lower() != "false":
        parts.append("built-in shared memory 512 KB + UDPv4 on all interfaces")
    return " + ".join(parts) if parts else "no transport"


def _describe_descriptor(desc: ET.Element, child: Callable[[ET.Element, str], ET.Element | None],
                         local: Callable[[str], str]) -> str:
    type_elem = child(desc, "type")
    kind = (type_elem.text or "").strip() if type_elem is not None else "?"
    if kind == "SHM":
        size = child(desc, "segment_size")
        n = int(size.text) if size is not None and size.text is not None and size.text.strip().isdigit() else 512 * 1024
        return f"shared memory {n // 2**20} MB" if n >= 2**20 else f"shared memory {n // 1024} KB"
    whitelist = child(desc, "interfaceWhiteList")
    allowed = [] if whitelist is None else [(c.text or "").strip() for c in whitelist if (c.text or "").strip()]
    interfaces = child(desc, "interfaces")
    if interfaces is not None:
        allow = child(interfaces, "allowlist")
        allowed += [] if allow is None else [c.get("name", "") for c in allow if local(c.tag) == "interface"]
    return f"{kind} on " + (", ".join(allowed) if allowed else "all interfaces")


def _profile_part(env: Mapping[str, str], cwd: Path) -> str:
    value = env.get(PROFILE_ENV, "")
    parts = []
    if value:
        path = Path(value)
        resolved = path.resolve() if path.exists() else path
        if resolved == PROFILE_PATH.resolve():
            parts.append(f"profile local (lightfast/ros/{PROFILE_PATH.name}: {_local_summary(PROFILE_PATH)})")
        elif resolved == NETWORK_PROFILE_PATH.resolve():
            parts.append(f"profile network (lightfast/ros/{NETWORK_PROFILE_PATH.name}: "
                         f"{describe_profile(NETWORK_PROFILE_PATH)})")
        elif path.name.startswith(GENERATED_PREFIX):
            parts.append(f"profile network (generated {path}: {describe_profile(path)})")
        else:
            parts.append(f"user profile {path} ({describe_profile(path)})")
    if env.get("SKIP_DEFAULT_XML_FILE", "")[:1] != "1" and (cwd / "DEFAULT_FASTRTPS_PROFILES.xml").is_file():
        extra = cwd / "DEFAULT_FASTRTPS_PROFILES.xml"
        parts.append(f"{'and ' if parts else ''}{extra} from the working directory ({describe_profile(extra)})")
    if not parts:
        parts.append("no profile (Fast DDS built-in shared memory 512 KB + UDPv4 on all interfaces)")
    return ", ".join(parts)


def _local_summary(path: Path) -> str:
    summary = describe_profile(path)
    return summary.replace("UDPv4 on 127.0.0.1", "UDP on loopback only")


def effective_discovery(env: Mapping[str, str]) -> tuple[str, list[str], str]:
    """(range, static peers in use, note) as rcl 9.2 and rmw_fastrtps 8.4 apply them to ``env``."""
    if env.get(LOCALHOST_ONLY_ENV, "")[:1] == "1":
        return "LOCALHOST", [], f"{LOCALHOST_ONLY_ENV}=1, deprecated, overrides {RANGE_ENV} and {PEERS_ENV}"
    value = env.get(RANGE_ENV, "")
    note = ""
    if value == "":
        discovery = "SUBNET"
        note = f"{RANGE_ENV} unset"
    elif value in ("OFF", "LOCALHOST", "SUBNET", "SYSTEM_DEFAULT"):
        discovery = value
    else:
        discovery = "LOCALHOST"
        note = f"unknown {RANGE_ENV}={value!r}"
    peers = [p for p in env.get(PEERS_ENV, "").split(";") if p] if discovery != "OFF" else []
    if discovery == "OFF" and env.get(PEERS_ENV):
        note = f"{PEERS_ENV} ignored"
    elif discovery == "LOCALHOST" and peers and not note:
        note = "rmw_fastrtps sends discovery to the peers over a UDP transport of its own, past any whitelist"
    return discovery, peers, note


def describe_transport(env: Mapping[str, str] = os.environ, *, domain_id: int | None = None,
                       cwd: Path | None = None) -> str:
    """One line saying which DDS transport and discovery a process with ``env`` uses, e.g. ``DDS: profile local
    (lightfast/ros/fastdds_local.xml: shared memory 64 MB + UDP on loopback only), discovery LOCALHOST, domain 0;
    for several machines see 'lightfast dds env --network'``. ``domain_id``: the id passed to rclpy, if any
    (default ``ROS_DOMAIN_ID``, else 0)."""
    rmw = env.get(RMW_ENV, "") or "rmw_fastrtps_cpp"
    if rmw in FASTRTPS_RMWS:
        head = "DDS: " + _profile_part(env, Path.cwd() if cwd is None else cwd)
        if rmw != "rmw_fastrtps_cpp":
            head += f" with {rmw}"
    else:
        head = f"DDS: {rmw} (Fast DDS profiles do not apply)"
    discovery, peers, note = effective_discovery(env)
    text = f"{head}, discovery {discovery}"
    if peers:
        text += " + static peers " + ", ".join(peers)
    if note:
        text += f" ({note})"
    if env.get("ROS_DISCOVERY_SERVER") and rmw in FASTRTPS_RMWS:
        text += f", discovery server {env['ROS_DISCOVERY_SERVER']}"
    if domain_id is None:
        raw = env.get(DOMAIN_ENV, "").strip()
        text += f", domain {raw if raw else 0}"
    else:
        text += f", domain {int(domain_id)}"
    if discovery in ("LOCALHOST", "OFF"):
        text += f"; {NETWORK_HINT}"
    return text
