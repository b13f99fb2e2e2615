"""A private Slurm cluster for the tests: MUNGE, slurmctld and slurmd started by the test on
this machine with their own configuration, ports, keys, state, spool and log folders under one
temporary folder, and stopped again by the test (only the processes it started).

One node on 127.0.0.1, or (``netns=True``) two nodes, each a network namespace of its own with a
veth pair into a bridge that the controller listens on: a job on node ``nb`` reaches the
controller and the shared file system, but its loopback and ports are its own. The namespaces,
veths and bridge are made (iproute2) and deleted by the test.

Nothing here touches /etc/slurm or /etc/munge or a system-wide daemon: the client commands find
this cluster through ``SLURM_CONF`` in :attr:`Cluster.env`.
"""
from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SBIN = "/usr/sbin"


def free_ports(n: int) -> list[int]:
    """n ports free on 127.0.0.1 now (held open together, so they differ)."""
    sockets = []
    try:
        for _ in range(n):
            s = socket.socket()
            s.bind(("127.0.0.1", 0))
            sockets.append(s)
        return [s.getsockname()[1] for s in sockets]
    finally:
        for s in sockets:
            s.close()


SLURM_CONF = """\
ClusterName={cluster}
SlurmctldHost={host}({ctld_addr})
SlurmctldPort={ctld_port}
SlurmdPort={slurmd_port}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
# cred_expire: a requeued job may start again after this many seconds (default 120)
AuthInfo=socket={munge_socket},cred_expire=5
StateSaveLocation={base}/state
SlurmdSpoolDir={base}/spool/%n
SlurmctldPidFile={base}/slurmctld.pid
SlurmdPidFile={base}/slurmd-%n.pid
SlurmctldLogFile={base}/log/slurmctld.log
SlurmdLogFile={base}/log/slurmd-%n.log
PlugStackConfig={base}/plugstack.conf
MailProg=/bin/true
# no cgroups: this may run in a container without a writable cgroup tree
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SchedulerType=sched/backfill
SchedulerParameters=sched_interval=2,bf_interval=1
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
# keep finished jobs' records: the tests read JobState and Restarts with scontrol
MinJobAge=86400
JobRequeue=1
KillWait=30
SlurmdParameters=config_overrides
{node_lines}
PartitionName=test Nodes={nodes} Default=YES MaxTime=INFINITE State=UP
"""


class Cluster:
    def __init__(self, netns: bool = False) -> None:
        self.netns = netns
        tag = os.getpid() % 10000
        if netns:  # (name, address, namespace); 10.237.<pid mod 250>.0/24 on bridge mlb<pid>
            net = f"10.237.{os.getpid() % 250}"
            self.bridge, self.ctld_addr = f"mlb{tag}", f"{net}.1"
            self.nodes = [(n, f"{net}.{i + 2}", f"mlslurm{tag}{n}") for i, n in enumerate(("na", "nb"))]
        else:
            self.bridge, self.ctld_addr = None, "127.0.0.1"
            self.nodes = [("n1", "127.0.0.1", None)]
        self.made: list[list[str]] = []  # ip commands that undo what was made
        # short path: the MUNGE socket's path must fit a sockaddr_un (108 bytes)
        self.base = Path(tempfile.mkdtemp(prefix="mlalike-slurm-"))
        self.procs: list[subprocess.Popen] = []
        self.env = {k: v for k, v in os.environ.items()
                    if k not in ("http_proxy", "https_proxy", "HTTP_PROXY", "HTTPS_PROXY", "grpc_proxy")
                    and not k.startswith("SLURM_")}
        self.env["SLURM_CONF"] = str(self.base / "slurm.conf")
        self.env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)

    # ------------------------------------------------------------------ start / stop
    def start(self) -> "Cluster":
        base = self.base
        for sub in ("munge", "state", "log", *[f"spool/{n}" for n, _, _ in self.nodes]):
            (base / sub).mkdir(parents=True, exist_ok=True)
        if self.netns:
            self._make_network()
        os.chmod(base / "munge", 0o700)
        (base / "plugstack.conf").write_text("")
        key = base / "munge" / "munge.key"
        key.write_bytes(os.urandom(1024))
        os.chmod(key, 0o400)
        self.munge_socket = base / "munge" / "munge.sock"
        self._spawn("munged", [f"{SBIN}/munged", "-F", "-f", f"--key-file={key}",
                               f"--socket={self.munge_socket}", f"--pid-file={base}/munge/munged.pid",
                               f"--log-file={base}/log/munged.log", f"--seed-file={base}/munge/seed"])
        self._wait(lambda: self.munge_socket.exists(), 20, "munged's socket")
        ctld_port, slurmd_port = free_ports(2)
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2**20
        host = socket.gethostname()
        memory = max(1024, int(memory * 0.8) // len(self.nodes))
        node_lines = "\n".join(f"NodeName={n} NodeHostname={host} NodeAddr={addr} CPUs={os.cpu_count()} "
                               f"RealMemory={memory} State=UNKNOWN" for n, addr, _ in self.nodes)
        (base / "slurm.conf").write_text(SLURM_CONF.format(
            cluster=f"mlalike{os.getpid()}", host=host, ctld_addr=self.ctld_addr, ctld_port=ctld_port,
            slurmd_port=slurmd_port, munge_socket=self.munge_socket, base=base, node_lines=node_lines,
            nodes=",".join(n for n, _, _ in self.nodes)))
        conf = self.env["SLURM_CONF"]
        self._spawn("slurmctld", [f"{SBIN}/slurmctld", "-D", "-i", "-f", conf])
        for name, _, ns in self.nodes:  # nsenter execs slurmd: the Popen is slurmd
            # nsenter, not `ip netns exec`: that also remounts /sys, without the cgroup tree slurmd reads
            prefix = ["nsenter", f"--net=/run/netns/{ns}"] if ns else []
            self._spawn(f"slurmd-{name}", [*prefix, f"{SBIN}/slurmd", "-D", "-f", conf, "-N", name])
        names = ",".join(n for n, _, _ in self.nodes)
        self._wait(lambda: self.run("sinfo", "-h", "-N", "-n", names, "-o", "%t", check=False).stdout.split()
                   == ["idle"] * len(self.nodes), 90, f"nodes {names} to be idle")
        return self

    def _ip(self, *args: str, undo: list[str] | None = None) -> None:
        r = subprocess.run(["ip", *args], capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"ip {' '.join(args)}: {r.stderr.strip()}")
        if undo:
            self.made.append(undo)

    def _make_network(self) -> None:
        self._ip("link", "add", "name", self.bridge, "type", "bridge", undo=["link", "del", self.bridge])
        self._ip("addr", "add", f"{self.ctld_addr}/24", "dev", self.bridge)
        self._ip("link", "set", self.bridge, "up")
        for i, (_, addr, ns) in enumerate(self.nodes):
            veth = f"{self.bridge}v{i}"
            self._ip("netns", "add", ns, undo=["netns", "del", ns])
            self._ip("link", "add", veth, "type", "veth", "peer", "name", "eth0", "netns", ns)
            self._ip("link", "set", veth, "master", self.bridge, "up")
            self._ip("-n", ns, "addr", "add", f"{addr}/24", "dev", "eth0")
            self._ip("-n", ns, "link", "set", "eth0", "up")
            self._ip("-n", ns, "link", "set", "lo", "up")

    def _spawn(self, name: str, cmd: list[str]) -> None:
        log = open(self.base / "log" / f"{name}.out", "wb")
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=self.env, start_new_session=True)
        log.close()
        proc.name = name  # type: ignore[attr-defined]
        self.procs.append(proc)

    def _wait(self, ready, timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not ready():
            for proc in self.procs:
                if proc.poll() is not None:
                    raise RuntimeError(f"{proc.name} exited with {proc.returncode} while waiting for {what}:\n"
                                       + self.logs())
            if time.monotonic() > deadline:
                raise TimeoutError(f"waited {timeout} s for {what}:\n" + self.logs())
            time.sleep(0.2)

    def logs(self) -> str:
        parts = []
        for path in sorted((self.base / "log").glob("*")):
            text = path.read_text(errors="replace")
            parts.append(f"--- {path.name}\n{text[-3000:]}")
        return "\n".join(parts)

    def stop(self) -> None:
        """Cancel this cluster's jobs, wait for their processes, stop the daemons we started."""
        if any(p.name == "slurmctld" and p.poll() is None for p in self.procs):
            self.run("scancel", "--user", str(os.getuid()), check=False)
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                states = self.run("squeue", "-h", "-o", "%T", check=False).stdout.split()
                if not states:
                    break
                time.sleep(0.5)
        for proc in reversed(self.procs):  # slurmd(s), slurmctld, munged
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        for undo in reversed(self.made):  # namespaces (their veth ends go with them), the bridge
            subprocess.run(["ip", *undo], capture_output=True)
        self.made.clear()
        shutil.rmtree(self.base, ignore_errors=True)

    # ------------------------------------------------------------------ client commands
    def run(self, *cmd: str, check: bool = True, **kw) -> subprocess.CompletedProcess:
        r = subprocess.run(cmd, env=kw.pop("env", self.env), capture_output=True, text=True, timeout=60, **kw)
        if check and r.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({r.returncode}): {r.stdout}{r.stderr}")
        return r

    def sbatch(self, *args: str, cwd: Path = ROOT) -> str:
        return self.run("sbatch", "--parsable", *args, cwd=cwd).stdout.strip().split(";")[0]

    def job(self, job_id: str) -> dict[str, str]:
        """scontrol show job, as a dict (JobState, Restarts, ExitCode, ...)."""
        out = self.run("scontrol", "show", "job", "-o", job_id).stdout
        return dict(re.findall(r"(\w+)=(\S*)", out))

    def wait_for_state(self, job_id: str, states: tuple[str, ...], timeout: float) -> dict[str, str]:
        deadline = time.monotonic() + timeout
        while True:
            info = self.job(job_id)
            if info.get("JobState") in states:
                return info
            if time.monotonic() > deadline:
                raise TimeoutError(f"job {job_id} not in {states} after {timeout} s: {info}\n" + self.logs())
            time.sleep(0.5)
