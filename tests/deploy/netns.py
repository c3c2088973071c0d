"""Several "hosts" on one Linux machine: network namespaces on a private LAN, for multi-host tests.

``Lan(["planning", "sim", "ar"])`` makes one network namespace per host, a bridge inside the first
one (the hub, where the router runs) and a veth link from every other host to that bridge, all with
addresses from a private 10.x subnet that exists only inside these namespaces. Every link is
created directly in the namespaces (``ip -n``), so the machine's own network is never touched.

    with Lan(["planning", "sim", "ar"]) as lan:
        lan["sim"].address                 # 10.231.N.2
        lan["sim"].argv(["python", ...])   # runs the command inside that host
        lan.cut("sim"); lan.heal("sim")    # take the host's link down / up (fault tests)

Processes started with ``lan.spawn("sim", argv)`` (a :class:`tests.procs.Proc` inside that host)
are stopped when the block is left, also on an exception; then the namespaces are deleted, which
removes their links.

Needs root and iproute2's ``ip``. :func:`require_netns` turns "cannot" into a test *failure* with the
reason, unless ``ARROCH_SKIP_NETNS=1`` deselects these tests explicitly (then they are skipped).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid
from dataclasses import dataclass
from types import TracebackType

import pytest

from tests.procs import Proc

SKIP_ENV = "ARROCH_SKIP_NETNS"


class NetnsError(RuntimeError):
    pass


def _ip(*args: str) -> None:
    result = subprocess.run(["ip", *args], capture_output=True, text=True)
    if result.returncode != 0:
        raise NetnsError(f"`ip {' '.join(args)}` failed: {result.stderr.strip() or result.stdout.strip()}")


def require_netns() -> None:
    """Skip when explicitly deselected; otherwise fail with the reason namespaces cannot be made."""
    if os.environ.get(SKIP_ENV) == "1":
        pytest.skip(f"{SKIP_ENV}=1: multi-host (network namespace) tests deselected explicitly")
    hint = f"run as root with iproute2 installed, or set {SKIP_ENV}=1 to deselect these tests explicitly"
    if shutil.which("ip") is None:
        pytest.fail(f"multi-host test needs the `ip` command (iproute2), which is not installed; {hint}", pytrace=False)
    if os.geteuid() != 0:
        pytest.fail(
            f"multi-host test needs root to create network namespaces (running as uid {os.geteuid()}); {hint}",
            pytrace=False,
        )


@dataclass
class Host:
    name: str
    netns: str  # kernel name of the namespace
    address: str  # its address on the LAN
    interface: str  # its LAN interface, inside its namespace

    def argv(self, command: list[str]) -> list[str]:
        """``command`` run inside this host (``ip netns exec`` execs it: same pid, same process group)."""
        return ["ip", "netns", "exec", self.netns, *command]


class Lan:
    """Hosts on one private LAN; the first host holds the bridge (and normally the router)."""

    def __init__(self, names: list[str], *, subnet: str | None = None) -> None:
        if len(names) < 2 or len(set(names)) != len(names):
            raise ValueError(f"need at least two distinct host names, got {names}")
        self.tag = uuid.uuid4().hex[:6]  # keeps parallel runs apart and names under 15 characters
        # A /24 picked per run inside 10.231.0.0/16, so two runs on one machine never share one.
        self.subnet = subnet or f"10.231.{int(self.tag[:2], 16)}"
        self.hosts: dict[str, Host] = {}
        for i, name in enumerate(names):
            iface = "br0" if i == 0 else "lan0"
            self.hosts[name] = Host(name, f"arr{self.tag}-{name[:8]}", f"{self.subnet}.{i + 1}", iface)
        self._created: list[str] = []
        self._procs: list[Proc] = []

    def __getitem__(self, name: str) -> Host:
        return self.hosts[name]

    @property
    def hub(self) -> Host:
        return next(iter(self.hosts.values()))

    def create(self) -> Lan:
        try:
            for host in self.hosts.values():
                _ip("netns", "add", host.netns)
                self._created.append(host.netns)
                _ip("-n", host.netns, "link", "set", "lo", "up")
            hub = self.hub
            _ip("-n", hub.netns, "link", "add", "br0", "type", "bridge")
            _ip("-n", hub.netns, "addr", "add", f"{hub.address}/24", "dev", "br0")
            _ip("-n", hub.netns, "link", "set", "br0", "up")
            for host in list(self.hosts.values())[1:]:
                port = f"p-{host.name[:10]}"
                # Both ends are born inside namespaces: the machine's own namespace never sees them.
                _ip(
                    "-n",
                    hub.netns,
                    "link",
                    "add",
                    port,
                    "type",
                    "veth",
                    "peer",
                    "name",
                    host.interface,
                    "netns",
                    host.netns,
                )
                _ip("-n", hub.netns, "link", "set", port, "master", "br0")
                _ip("-n", hub.netns, "link", "set", port, "up")
                _ip("-n", host.netns, "addr", "add", f"{host.address}/24", "dev", host.interface)
                _ip("-n", host.netns, "link", "set", host.interface, "up")
        except NetnsError as exc:
            self.destroy()
            pytest.fail(
                f"could not build the namespace LAN: {exc}; run as root with iproute2, "
                f"or set {SKIP_ENV}=1 to deselect these tests explicitly",
                pytrace=False,
            )
        return self

    def spawn(self, host: str, argv: list[str], *, name: str = "", env: dict[str, str] | None = None) -> Proc:
        """Start ``argv`` inside ``host``; it is stopped before the LAN is taken down."""
        proc = Proc(self.hosts[host].argv(argv), env=env, name=name or host)
        self._procs.append(proc)
        return proc

    def cut(self, name: str) -> None:
        """Take a host's LAN link down (its processes stay up, their traffic goes nowhere)."""
        host = self.hosts[name]
        _ip("-n", host.netns, "link", "set", host.interface, "down")

    def heal(self, name: str) -> None:
        host = self.hosts[name]
        _ip("-n", host.netns, "link", "set", host.interface, "up")

    def destroy(self) -> None:
        """Stop the processes started in it, then delete every namespace it made (links go with them)."""
        for proc in reversed(self._procs):
            proc.stop()
        self._procs.clear()
        errors = []
        for netns in reversed(self._created):
            try:
                _ip("netns", "del", netns)
            except NetnsError as exc:
                errors.append(str(exc))
        self._created.clear()
        if errors:
            raise NetnsError("; ".join(errors))

    def __enter__(self) -> Lan:
        return self.create()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.destroy()
