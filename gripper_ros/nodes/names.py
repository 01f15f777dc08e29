"""One gripper per namespace: a node or graph refuses to start where its names are taken.

Two checks, before anything is published:

- a claim on this machine: one lock file per (domain, namespace, node name), held with
  ``flock`` while the node lives, so a second plant or supervisor in the namespace is refused
  at once, in this process or another, and a killed process frees its names. The namespace's
  parts are nested folders (a part holds only letters, digits and ``_``), so two namespaces
  never share a folder (``a/b`` and ``a_b``);
- discovery: the node names and service servers already on the domain in the namespace, which
  also finds a gripper on another host. DDS discovery across processes can take seconds, so
  this check alone would let a graph started right after another one through.

A graph also claims its TF prefix on this machine (the frames and the joint it publishes), so
that a second namespace with the same prefix (``a/b`` and ``a_b``) is refused.

The probe that asks the domain keeps its own name under a global ``-r __node:=NAME`` remap
(how ``launch_ros`` names a node), else it would find itself under the claimed name.
"""
from __future__ import annotations

import fcntl
import os
from pathlib import Path
import tempfile
import time

from gripper_ros.nodes.startup import StartupError
from gripper_ros.wire import DEFAULT_NAMESPACE, qualified
from rclpy.node import Node

DISCOVERY_WAIT_S = 0.5
"""How long a start-up looks on the domain for a gripper claimed elsewhere (it stops at the
first sign of one). A participant that has just joined often learns of the others only at their
next announcement, up to Fast DDS's 3 s period later: a shorter look is best effort."""
DISCOVERY_CONFIRM_S = 1.0
"""What discovery shows must still be there this long after it first showed: a node that was just
shut down has left the graph by then and is not mistaken for a running one, and the rest of a
running graph (its services) has been discovered too."""
DISCOVERY_POLL_S = 0.05
PROBE_NODE = 'gripper_startup_probe'


def claims_dir() -> Path:
    """Where the claims of this user live (``GRIPPER_ROS_CLAIMS_DIR`` overrides it)."""
    base = os.environ.get('GRIPPER_ROS_CLAIMS_DIR') or \
        os.path.join(os.environ.get('XDG_RUNTIME_DIR') or tempfile.gettempdir(),
                     f'gripper_ros_claims.{os.getuid()}')
    return Path(base)


class NameClaim:
    """The names of one node or graph in its namespace on its domain, held while it runs."""

    def __init__(self, files: list):
        self._files = files

    @classmethod
    def take(cls, node_names: tuple[str, ...], services: tuple[str, ...] = (), context=None,
             namespace: str | None = None, prefix: str | None = None) -> NameClaim:
        """Claim ``node_names`` in ``namespace``, or raise StartupError if one is taken.

        ``namespace`` defaults to the default one as the command line remaps it
        (``-r __ns:=/left``). The StartupError names what is found when one of the nodes, or a
        server of one of the relative ``services``, exists already. With ``prefix`` (the TF
        frames' and the joint's, ``wire.namespace_prefix``) the prefix is claimed as well: a
        graph of another namespace on this machine that publishes the same frames (``a/b`` and
        ``a_b`` both give ``a_b_``) refuses this one.
        """
        import rclpy
        ctx = context or rclpy.get_default_context()
        domain = ctx.get_domain_id()
        probe = None

        def make_probe():
            return probe_node(DEFAULT_NAMESPACE if namespace is None else namespace, context)

        claim = None
        try:
            if namespace is None:              # as the command line remaps it: ask a node
                probe = make_probe()
                where = probe.get_namespace()
            else:
                where = '/' + namespace.strip('/')
            claim, held = cls._lock(domain, where, node_names)
            found = held
            if not held:                       # no claim here: ask the domain's discovery
                probe = probe or make_probe()
                found = taken_names(probe, node_names, services)
        finally:
            if probe is not None:
                retire_probe(probe)
        if found:
            if claim is not None:
                claim.release()
            raise StartupError(f'namespace {where} is taken on ROS_DOMAIN_ID {domain}: found '
                               f'{", ".join(found)}')
        other = None if prefix is None else claim._hold_prefix(domain, where, prefix)
        if other is not None:
            claim.release()
            raise StartupError(f'prefix {prefix!r} of namespace {where} is taken on '
                               f'ROS_DOMAIN_ID {domain} by namespace {other} on this machine: '
                               'both would publish the same TF frames and joint; give one '
                               'another prefix (-p prefix:=NAME_)')
        return claim

    def _hold_prefix(self, domain: int, namespace: str, prefix: str) -> str | None:
        """Hold ``prefix`` for ``namespace``; return another namespace holding it, else None.

        One lock file per namespace in the prefix's folder, held shared by each process of the
        namespace; a file another process holds is a live graph of that namespace.
        """
        folder = claims_dir() / f'domain_{domain}' / 'prefix' / (prefix or '-')
        folder.mkdir(parents=True, exist_ok=True)
        mine = (namespace.strip('/').replace('/', '-') or '-') + '.lock'   # '-': in no name
        f = open(folder / mine, 'a+')  # noqa: SIM115 - held until release()
        fcntl.flock(f, fcntl.LOCK_SH)
        self._files.append(f)
        for path in sorted(folder.glob('*.lock')):
            if path.name == mine:
                continue
            with open(path, 'a+') as other:
                try:
                    fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    return '/' + path.stem.replace('-', '/').strip('/')
        return None

    @classmethod
    def _lock(cls, domain: int, namespace: str, node_names) -> tuple[NameClaim, list[str]]:
        folder = claim_folder(domain, namespace)
        folder.mkdir(parents=True, exist_ok=True)
        files, held = [], []
        for name in node_names:
            f = open(folder / f'{name}.lock', 'a+')  # noqa: SIM115 - held until release()
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                f.seek(0)
                owner = f.read().strip()
                f.close()
                held.append(f'{qualified(namespace.strip("/"), name)}'
                            + (f' (process {owner} on this machine)' if owner else ''))
                continue
            f.seek(0)
            f.truncate()
            f.write(str(os.getpid()))
            f.flush()
            files.append(f)
        return cls(files), held

    def release(self) -> None:
        """Give the names up (also done by the system when the process ends)."""
        for f in self._files:
            try:
                f.close()
            except OSError:
                pass
        self._files = []


GRASP_ID_FILE = 'supervisor.last_grasp_id'
GRASP_ID_MAX = 2 ** 32 - 1
"""The wire's grasp_id is uint32: past it, ids start again from 1."""


class GraspIds:
    """The last request id a namespace's supervisor gave, kept beside the namespace's claims.

    A restarted supervisor numbers its requests on from there, so the bags and statuses of one
    namespace never carry one id twice while the claims folder lasts (it is in
    ``XDG_RUNTIME_DIR``, or the temporary folder: a reboot or a logout may clear it).
    """

    def __init__(self, domain: int, namespace: str, warn=None):
        self.path = claim_folder(domain, namespace) / GRASP_ID_FILE
        self._warn = warn
        self._warned = False

    def last(self) -> int:
        """Return the last id given in the namespace: 0 when none is kept or it is unreadable."""
        try:
            value = int(self.path.read_text(encoding='ascii').strip())
        except (OSError, ValueError):
            return 0
        return value if 0 <= value < GRASP_ID_MAX else 0

    def save(self, grasp_id: int) -> None:
        """Keep ``grasp_id`` as the last one given (atomically; a failure only warns once)."""
        tmp = self.path.with_name(f'{self.path.name}.{os.getpid()}.tmp')
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(f'{int(grasp_id)}\n', encoding='ascii')
            os.replace(tmp, self.path)
        except OSError as exc:
            if self._warn is not None and not self._warned:
                self._warn(f'cannot keep the last grasp id in {self.path} ({exc.strerror}): a '
                           'restarted supervisor would number its requests from 1 again')
                self._warned = True


def claim_folder(domain: int, namespace: str) -> Path:
    """Return the folder of the claims in ``namespace``: one nested folder per namespace part.

    Parts hold only letters, digits and ``_`` (``wire.check_namespace``), so no two namespaces
    map to one folder, and no part is longer than a file name may be.
    """
    folder = claims_dir() / f'domain_{domain}' / 'ns'
    for part in namespace.strip('/').split('/'):
        if part:
            folder = folder / part
    return folder


def namespace_as_given(default: str = DEFAULT_NAMESPACE, context=None) -> str:
    """Return the namespace a node made with ``default`` gets, after the command line's remaps.

    One source of truth for a graph whose namespace may come from an option or from
    ``--ros-args -r __ns:=/x``: ask a node (the remap wins, as for every ROS node).
    """
    probe = probe_node(default, context)
    try:
        return probe.get_namespace().strip('/')
    finally:
        retire_probe(probe)


_RETIRED_PROBES: list = []
"""Start-up probes set aside by :func:`retire_probe`, destroyed by :func:`destroy_probes`."""


def retire_probe(probe: Node) -> None:
    """Set a start-up probe aside until a node of its own is built in its context.

    The last node of a context takes the context's DDS participant with it, and Fast DDS 2.14
    deletes a participant by spinning until no discovery callback runs
    (``DomainParticipantImpl::set_listener`` with its infinite timeout; eProsima/Fast-DDS#6513):
    amid the discovery of many starting processes the callback it waits for is starved, and the
    start spins for good. Destroyed beside a live node, a probe takes no participant with it.
    """
    _RETIRED_PROBES.append(probe)


def destroy_probes(context=None) -> None:
    """Destroy the probes set aside in ``context`` (default: rclpy's).

    Called once a node of the context's own lives there, or when the context is given up.
    """
    import rclpy
    ctx = context or rclpy.get_default_context()
    mine = [p for p in _RETIRED_PROBES if p.context is ctx]
    _RETIRED_PROBES[:] = [p for p in _RETIRED_PROBES if p.context is not ctx]
    for probe in mine:
        probe.destroy_node()


def probe_node(namespace: str = DEFAULT_NAMESPACE, context=None) -> Node:
    """Make the short-lived start-up node, in ``namespace`` as the command line remaps it.

    It keeps its own name (:func:`keep_name_args`), starts no parameter services and no
    rosout; the caller retires it (:func:`retire_probe`) once it has asked what it needs.
    """
    import rclpy
    kw = {'context': context} if context is not None else {}
    return rclpy.create_node(PROBE_NODE, namespace=namespace, enable_rosout=False,
                             start_parameter_services=False, cli_args=keep_name_args(PROBE_NODE),
                             **kw)


def taken_names(node: Node, node_names: tuple[str, ...] = (), services: tuple[str, ...] = (),
                wait_s: float | None = None) -> list[str]:
    """Return which of ``node_names`` and relative ``services`` exist in ``node``'s namespace.

    A service counts when it has a server (a client waiting for one is welcome). Discovery is
    watched for up to ``wait_s`` (default :data:`DISCOVERY_WAIT_S`) until one shows; what shows
    must still be there :data:`DISCOVERY_CONFIRM_S` later.
    """
    found = _watch(node, node_names, services, time.monotonic() + (
        DISCOVERY_WAIT_S if wait_s is None else wait_s), until_found=True)
    if not found:
        return []
    return _watch(node, node_names, services, time.monotonic() + DISCOVERY_CONFIRM_S,
                  until_found=False)


def _watch(node: Node, node_names, services, deadline_s: float, until_found: bool) -> list[str]:
    """Look until something is found (or, ``until_found`` False, until nothing is) or the end."""
    while True:
        found = _present(node, node_names, services)
        if bool(found) == until_found or time.monotonic() >= deadline_s:
            return found
        time.sleep(DISCOVERY_POLL_S)


def _present(node: Node, node_names, services) -> list[str]:
    """Return which of ``node_names`` and ``services`` discovery shows now in the namespace."""
    namespace = node.get_namespace()
    nodes = {(ns.rstrip('/') or '/', n) for n, ns in node.get_node_names_and_namespaces()}
    ours = namespace.rstrip('/') or '/'
    found = [qualified(namespace.strip('/'), n) for n in node_names if (ours, n) in nodes]
    names = {s for s, _ in node.get_service_names_and_types()}   # clients' names too
    found += [f'service {name}' for name in
              (qualified(namespace.strip('/'), s) for s in services)
              if name in names and node.count_services(name) > 0]
    return found


def keep_name_args(node_name: str) -> list[str]:
    """Node arguments that keep ``node_name`` under a global ``-r __node:=OTHER`` remap.

    ``launch_ros`` names a node with a global remap, which renames every node of the process;
    a node's own arguments are looked up first, so a helper node keeps its name with these.
    """
    return ['--ros-args', '-r', f'__node:={node_name}']


def default_namespace(kwargs: dict) -> dict:
    """Return Node keyword arguments with the package's namespace unless one is given.

    A remap ``-r __ns:=/left`` still wins, as for every ROS node.
    """
    kwargs.setdefault('namespace', DEFAULT_NAMESPACE)
    return kwargs
