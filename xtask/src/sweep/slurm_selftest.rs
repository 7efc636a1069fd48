//! `cargo xtask sweep slurm-selftest`: a real single-node Slurm on this machine (Debian's `slurm-wlm`:
//! munged, slurmctld and slurmd on localhost with a private configuration under
//! `target/sweeps/slurm-selftest/`) runs the job array `--emit slurm` writes for the tiny `loss` sweep,
//! then checks that every run completed and that `--collect` reports them. Not part of CI: it installs
//! system packages and starts daemons, which it stops again.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::util::{Result, is_root, spawn};

/// The `slurm.conf` of one node named `host` with `cpus` CPUs, everything kept under `dir`.
pub fn slurm_conf(host: &str, cpus: usize, dir: &Path) -> String {
    let d = dir.display();
    format!(
        "ClusterName=hush-selftest
SlurmctldHost={host}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation={d}/state
SlurmdSpoolDir={d}/spool
SlurmctldPidFile={d}/slurmctld.pid
SlurmdPidFile={d}/slurmd.pid
SlurmctldLogFile={d}/slurmctld.log
SlurmdLogFile={d}/slurmd.log
SlurmctldPort=46817
SlurmdPort=46818
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} State=UNKNOWN
PartitionName=selftest Nodes={host} Default=YES MaxTime=INFINITE State=UP
"
    )
}

fn have(program: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {program}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn munge_works() -> bool {
    Command::new("sh")
        .args(["-c", "munge -n | unmunge"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Daemons started here, stopped (by their own process ids) when dropped.
pub struct Daemons(Vec<(String, Child)>);

impl Drop for Daemons {
    fn drop(&mut self) {
        // In reverse order, each first asked to stop (SIGTERM lets slurmctld reap its script helper).
        for (name, child) in self.0.iter_mut().rev() {
            let _ = Command::new("kill").args(["-TERM", &child.id().to_string()]).status();
            let start = Instant::now();
            while child.try_wait().ok().flatten().is_none() && start.elapsed() < Duration::from_secs(10) {
                std::thread::sleep(Duration::from_millis(100));
            }
            let _ = child.kill();
            let _ = child.wait();
            eprintln!("slurm-selftest: stopped {name}");
        }
    }
}

/// Installs Slurm if needed, starts munged (if no munge daemon answers), slurmctld and slurmd, waits for
/// the node to be idle and returns the daemons and the configuration file.
pub fn start(dir: &Path) -> Result<(Daemons, std::path::PathBuf)> {
    if !have("sbatch") || !have("slurmd") || !have("munged") {
        if !(is_root() && Path::new("/usr/bin/apt-get").exists()) {
            return Err("Slurm is not installed: `sudo apt-get install -y slurm-wlm` (Debian), then re-run".into());
        }
        spawn(
            Command::new("apt-get")
                .args(["install", "-y", "-qq", "slurm-wlm"])
                .env("DEBIAN_FRONTEND", "noninteractive"),
        )?;
    }
    for sub in ["state", "spool"] {
        std::fs::create_dir_all(dir.join(sub)).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let host = String::from_utf8_lossy(
        &Command::new("hostname").arg("-s").output().map_err(|e| format!("hostname: {e}"))?.stdout,
    )
    .trim()
    .to_string();
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let conf = dir.join("slurm.conf");
    crate::util::write_atomic(&conf, &slurm_conf(&host, cpus, dir))?;

    let mut daemons = Daemons(Vec::new());
    if !munge_works() {
        // munged refuses to run as root without --force; it needs its socket directory.
        std::fs::create_dir_all("/run/munge").map_err(|e| format!("/run/munge: {e}"))?;
        let _ = Command::new("chown").args(["munge:munge", "/run/munge"]).status();
        let child = Command::new("munged")
            .args(["--foreground", "--force"])
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| format!("cannot start munged: {e}"))?;
        daemons.0.push(("munged".into(), child));
        let start = Instant::now();
        while !munge_works() {
            if start.elapsed() > Duration::from_secs(10) {
                return Err("munged does not answer (`munge -n | unmunge` fails); see /var/log/munge".into());
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }
    for daemon in ["slurmctld", "slurmd"] {
        let log =
            std::fs::File::create(dir.join(format!("{daemon}.out"))).map_err(|e| format!("{}: {e}", dir.display()))?;
        let child = Command::new(daemon)
            .arg("-D")
            .arg("-f")
            .arg(&conf)
            .env("SLURM_CONF", &conf)
            .stdout(log.try_clone().map_err(|e| e.to_string())?)
            .stderr(log)
            .spawn()
            .map_err(|e| format!("cannot start {daemon}: {e}"))?;
        daemons.0.push((daemon.into(), child));
        std::thread::sleep(Duration::from_secs(1));
    }
    let start = Instant::now();
    loop {
        let out = Command::new("sinfo").args(["-h", "-o", "%T"]).env("SLURM_CONF", &conf).output();
        let state = out.map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string()).unwrap_or_default();
        if state == "idle" {
            break;
        }
        if start.elapsed() > Duration::from_secs(60) {
            return Err(format!(
                "the Slurm node is `{state}`, not idle, after 60 s; see {}/slurmctld.log and slurmd.log",
                dir.display()
            ));
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    eprintln!("slurm-selftest: single-node Slurm is up ({host}, {cpus} CPUs; {})", conf.display());
    Ok((daemons, conf))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_node_with_its_files_in_one_folder() {
        let conf = slurm_conf("box", 2, Path::new("/t/s"));
        for line in [
            "SlurmctldHost=box\n",
            "NodeName=box NodeAddr=127.0.0.1 CPUs=2 State=UNKNOWN\n",
            "PartitionName=selftest Nodes=box Default=YES MaxTime=INFINITE State=UP\n",
            "StateSaveLocation=/t/s/state\n",
            "SlurmdSpoolDir=/t/s/spool\n",
            "AuthType=auth/munge\n",
        ] {
            assert!(conf.contains(line), "missing {line:?}");
        }
    }
}
