"""A one-node SLURM cluster on this machine, for the tests: munged, slurmctld and slurmd.

    with SlurmCluster(tmp_path) as cluster:
        subprocess.run(["sbatch", "--wrap", "hostname"], env=cluster.env())

Everything lives under one directory: slurm.conf, a fresh munge key, the munge socket, state and
spool directories, pid files and the daemons' logs. The controller and the node listen on
127.0.0.1 on ports chosen free at start, so the cluster neither needs nor touches /etc/slurm,
/run/munge or a system munged, and two clusters on one machine do not meet. Clients (sbatch,
squeue, sinfo, and so the Snakemake SLURM executor plugin) find it through SLURM_CONF, which
`env()` sets. One client loses it: inside a job, snakemake-executor-plugin-slurm-jobstep (0.6.1)
removes every SLURM_* variable but the job's identity before it starts the rule with `srun`, so
that srun would look for /etc/slurm/slurm.conf. `env()` therefore also puts first on PATH a
two-line `srun` that sets SLURM_CONF again and runs the real one; sbatch passes PATH to the jobs.
(A site whose slurm.conf is where SLURM looks by default, or that runs configless, needs nothing
of the kind.)

The daemons run in the foreground (munged -F, slurmctld -D, slurmd -D) as children of this
process, so each is known by the pid of its Popen and stopped by that pid: SIGTERM, a wait, SIGKILL
only if it did not end. Nothing is ever killed by name. Jobs still queued or running are cancelled
(scancel) before slurmd stops, so no job step outlives the cluster.

Needs root (slurmd starts jobs as their user) and Debian's packages, SLURM 22.05 and MUNGE:
`apt-get install -y --no-install-recommends slurmctld slurmd slurm-client munge` (`.ci/run` does
it). There is no accounting daemon: `sacct` exists but cannot answer, so the Snakemake executor
must be told to use `squeue` for job states (`--slurm-status-command squeue`), which works while a
finished job is kept by slurmctld for MinJobAge (set here to 600 s).
"""
from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

DAEMONS = ("munged", "slurmctld", "slurmd")
CLIENTS = ("sbatch", "squeue", "sinfo", "scontrol", "scancel", "srun")
PACKAGES = ("slurmctld", "slurmd", "slurm-client", "munge")
MIN_JOB_AGE = 600   # seconds a finished job stays visible to squeue


class ClusterError(RuntimeError):
    """The cluster did not come up; the message ends with the tails of the daemons' logs."""


def missing_programs() -> list[str]:
    return [name for name in DAEMONS + CLIENTS
            if shutil.which(name) is None and not Path("/usr/sbin", name).exists()]


def program(name: str) -> str:
    """Full path of a SLURM or MUNGE program (the daemons live in /usr/sbin, not always on PATH)."""
    found = shutil.which(name) or str(Path("/usr/sbin", name))
    if not Path(found).exists():
        raise ClusterError(f"{name} not found: install {' '.join(PACKAGES)}")
    return found


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def node_line() -> str:
    """This machine's hardware as slurmd sees it ("CPUs=2 Boards=1 ... RealMemory=24105")."""
    described = subprocess.run([program("slurmd"), "-C"], capture_output=True, text=True,
                               check=True, timeout=30).stdout.splitlines()[0]
    return " ".join(field for field in described.split() if not field.startswith("NodeName="))


class SlurmCluster:
    """munged + slurmctld + slurmd on 127.0.0.1, configured and kept under `directory`."""

    def __init__(self, directory: Path, partition: str = "debug", start_timeout: float = 60.0):
        self.directory = Path(directory)
        self.partition = partition
        self.start_timeout = start_timeout
        self.node = socket.gethostname().split(".")[0]
        self.processes: dict[str, subprocess.Popen] = {}
        self.conf = self.directory / "etc" / "slurm.conf"
        self.munge_socket = self.directory / "munge" / "munge.socket"

    # -- configuration ---------------------------------------------------------------------------

    def write_configuration(self) -> None:
        for sub in ("etc", "munge", "state", "spool", "log", "run", "bin"):
            (self.directory / sub).mkdir(parents=True, exist_ok=True)
        for sub in ("munge", "etc"):
            os.chmod(self.directory / sub, 0o700)
        key = self.directory / "etc" / "munge.key"
        key.write_bytes(os.urandom(128))
        os.chmod(key, 0o600)
        d = self.directory
        self.conf.write_text(f"""\
# a one-node test cluster, written by tests/slurm_cluster.py
ClusterName=colsimtest
SlurmctldHost={self.node}(127.0.0.1)
SlurmctldPort={free_port()}
SlurmdPort={free_port()}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={self.munge_socket}
StateSaveLocation={d / 'state'}
SlurmdSpoolDir={d / 'spool'}
SlurmctldPidFile={d / 'run' / 'slurmctld.pid'}
SlurmdPidFile={d / 'run' / 'slurmd.pid'}
SlurmctldLogFile={d / 'log' / 'slurmctld.log'}
SlurmdLogFile={d / 'log' / 'slurmd.log'}
PlugStackConfig={d / 'etc' / 'plugstack.conf'}
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SwitchType=switch/none
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
ReturnToService=2
MinJobAge={MIN_JOB_AGE}
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
KillWait=5
NodeName={self.node} NodeAddr=127.0.0.1 {node_line()} State=UNKNOWN
PartitionName={self.partition} Nodes={self.node} Default=YES MaxTime=INFINITE State=UP
""")
        (d / "etc" / "plugstack.conf").write_text("")
        srun = d / "bin" / "srun"
        srun.write_text(f'#!/bin/sh\n# this test cluster\'s srun (see tests/slurm_cluster.py)\n'
                        f'SLURM_CONF="{self.conf}" exec {program("srun")} "$@"\n')
        os.chmod(srun, 0o755)

    def env(self, base: dict | None = None) -> dict:
        """The environment for SLURM clients of this cluster: SLURM_CONF set, the srun shim first on
        PATH, SLURM_* variables of any enclosing job removed."""
        env = {k: v for k, v in (os.environ if base is None else base).items()
               if not k.startswith(("SLURM_", "SBATCH_", "SRUN_", "SQUEUE_"))}
        env["SLURM_CONF"] = str(self.conf)
        env["PATH"] = os.pathsep.join([str(self.directory / "bin"), env.get("PATH", "")])
        return env

    # -- daemons ---------------------------------------------------------------------------------

    def _start(self, name: str, *arguments: str) -> None:
        log = open(self.directory / "log" / f"{name}.stdout", "ab")
        try:
            self.processes[name] = subprocess.Popen(
                [program(name), *arguments], stdin=subprocess.DEVNULL, stdout=log,
                stderr=subprocess.STDOUT, env=self.env(), start_new_session=True)
        finally:
            log.close()

    def _wait_for(self, what: str, ready) -> None:
        deadline = time.monotonic() + self.start_timeout
        while time.monotonic() < deadline:
            for name, process in self.processes.items():
                if process.poll() is not None:
                    raise ClusterError(f"{name} exited with status {process.returncode} while "
                                       f"waiting for {what}\n{self.log_tails()}")
            if ready():
                return
            time.sleep(0.2)
        raise ClusterError(f"timed out after {self.start_timeout:.0f} s waiting for {what}\n"
                           f"{self.log_tails()}")

    def _client(self, *command: str, timeout: float = 30) -> subprocess.CompletedProcess:
        return subprocess.run(list(command), capture_output=True, text=True, env=self.env(),
                              timeout=timeout)

    def node_state(self) -> str:
        result = self._client("sinfo", "--noheader", "--Node", "--format=%T")
        return result.stdout.strip() if result.returncode == 0 else ""

    def start(self) -> "SlurmCluster":
        self.write_configuration()
        d = self.directory
        self._start("munged", "--foreground", "--force", f"--socket={self.munge_socket}",
                    f"--key-file={d / 'etc' / 'munge.key'}", f"--pid-file={d / 'run' / 'munged.pid'}",
                    f"--log-file={d / 'log' / 'munged.log'}", f"--seed-file={d / 'munge' / 'munged.seed'}")
        self._wait_for("the munge socket", self.munge_socket.exists)
        self._start("slurmctld", "-D", "-f", str(self.conf))
        self._wait_for("slurmctld", lambda: "UP" in self._client("scontrol", "ping").stdout)
        self._start("slurmd", "-D", "-f", str(self.conf), "-N", self.node)
        self._wait_for(f"node {self.node} idle", lambda: self.node_state() == "idle")
        return self

    def cancel_jobs(self, timeout: float = 60.0) -> None:
        """Cancel every job of this cluster and wait until none is running or being cleaned up."""
        if "slurmctld" not in self.processes or self.processes["slurmctld"].poll() is not None:
            return
        self._client("scancel", "--full", "--user", "root")
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            listed = self._client("squeue", "--noheader", "--states=PENDING,RUNNING,COMPLETING,"
                                  "CONFIGURING,SUSPENDED", "--format=%i")
            if listed.returncode != 0 or not listed.stdout.strip():
                return
            time.sleep(0.5)

    def stop(self) -> None:
        """Stop the daemons this object started, by pid, in reverse order."""
        self.cancel_jobs()
        for name in reversed(DAEMONS):
            process = self.processes.pop(name, None)
            if process is None or process.poll() is not None:
                continue
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(timeout=10)

    @property
    def pids(self) -> dict[str, int]:
        return {name: process.pid for name, process in self.processes.items()}

    def log_tails(self, lines: int = 15) -> str:
        tails = []
        for path in sorted((self.directory / "log").glob("*")):
            text = path.read_text(errors="replace").splitlines()[-lines:]
            if text:
                tails.append(f"--- {path.name}\n" + "\n".join(text))
        return "\n".join(tails)

    def __enter__(self) -> "SlurmCluster":
        try:
            return self.start()
        except BaseException:
            self.stop()
            raise

    def __exit__(self, *exc) -> None:
        self.stop()
