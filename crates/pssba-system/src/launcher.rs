//! `pssba run`: starts the four stages as processes of the `pssba` binary (`pssba stage ...`),
//! gives the run its own iceoryx2 prefix, supervises them (a thread per child reports its
//! exit on a channel; no polling), forwards Ctrl-C/SIGTERM, and stops everything if a stage
//! dies, naming it.

use crate::RunConfig;
use crate::source::SourceSpec;
use anyhow::{Context, bail};
use crossbeam_channel::{Receiver, Sender, unbounded};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Stage names, in start order (consumers first).
pub const STAGES: [&str; 4] = ["record", "adjust", "smooth", "ingest"];

/// What to run.
#[derive(Debug, Clone)]
pub struct LaunchOptions {
    /// The `pssba` executable whose `stage` subcommands are the stages.
    pub exe: PathBuf,
    /// Effective configuration (written next to the MCAP file and given to every stage).
    pub config: RunConfig,
    /// Where the frames come from.
    pub source: SourceSpec,
    /// Output MCAP file.
    pub out: PathBuf,
    /// Ingest rate (Hz); `None` = as fast as the consumers take frames.
    pub rate_hz: Option<f64>,
    /// Log verbosity passed to the stages (`-v` count).
    pub verbose: u8,
    /// Stop after this long (watchdog); `None` = no limit.
    pub timeout: Option<Duration>,
}

impl LaunchOptions {
    /// Frames come from outside producers: no ingest stage.
    pub fn live(&self) -> bool {
        matches!(self.source, SourceSpec::Live(_))
    }
}

enum Event {
    Exited(usize, std::io::Result<ExitStatus>),
    Signal,
}

/// A prefix unique to this run (process id and clock), so runs never share services.
pub fn unique_prefix() -> String {
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    format!("pssba-{}-{nanos}-", std::process::id())
}

fn stage_command(
    options: &LaunchOptions,
    stage: &str,
    prefix: &str,
    config_path: &Path,
) -> Command {
    let mut command = Command::new(&options.exe);
    command
        .arg("stage")
        .arg(stage)
        .arg("--prefix")
        .arg(prefix)
        .arg("--config")
        .arg(config_path);
    for _ in 0..options.verbose {
        command.arg("-v");
    }
    match stage {
        "record" => {
            command.arg("--out").arg(&options.out);
            if options.live() {
                command.arg("--live");
            }
        }
        "smooth" if options.live() => {
            command.arg("--live");
        }
        "ingest" => {
            command.arg("--source").arg(options.source.to_string());
            if let Some(rate) = options.rate_hz {
                command.arg("--rate").arg(rate.to_string());
            }
        }
        _ => {}
    }
    command
}

fn signal_all(children: &[(usize, u32)], running: &[bool], signal: Signal) {
    for &(index, pid) in children {
        if running[index] {
            // The child may have exited in between; nothing to do then.
            let _ = kill(Pid::from_raw(pid as i32), signal);
        }
    }
}

/// Runs the system to completion. Returns the effective config path.
pub fn launch(options: &LaunchOptions) -> anyhow::Result<PathBuf> {
    if let Some(parent) = options.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    let config_path = options.out.with_extension("config.toml");
    std::fs::write(&config_path, options.config.to_toml()?)
        .with_context(|| format!("writing {}", config_path.display()))?;
    // A live instance has a fixed prefix that outside producers and subscribers use.
    let prefix = match &options.source {
        SourceSpec::Live(instance) => pssba_client::instance::prefix(instance),
        _ => unique_prefix(),
    };
    if let SourceSpec::Live(instance) = &options.source {
        let system: Vec<String> = pssba_msg::services::alive_node_names(&prefix)?
            .into_iter()
            .filter(|n| STAGES.contains(&n.as_str()))
            .collect();
        if !system.is_empty() {
            bail!(
                "live instance {instance} is in use: stages {} of another `pssba run` are \
                 attached to it; stop that run or choose another --instance",
                system.join(", ")
            );
        }
    }
    let (sender, receiver): (Sender<Event>, Receiver<Event>) = unbounded();
    let signal_sender = sender.clone();
    // Ctrl-C / SIGTERM: forward to the stages and let them finish the MCAP file.
    ctrlc::set_handler(move || {
        let _ = signal_sender.send(Event::Signal);
    })
    .context("installing the Ctrl-C handler")?;

    let mut pids = Vec::new();
    let mut running = [false; STAGES.len()];
    for (index, stage) in STAGES.iter().enumerate() {
        if *stage == "ingest" && options.live() {
            continue;
        }
        let child: Child = stage_command(options, stage, &prefix, &config_path)
            .spawn()
            .with_context(|| format!("starting stage {stage} ({})", options.exe.display()))?;
        pids.push((index, child.id()));
        running[index] = true;
        let sender = sender.clone();
        std::thread::spawn(move || {
            let mut child = child;
            let status = child.wait();
            let _ = sender.send(Event::Exited(index, status));
        });
    }
    tracing::info!("started {} stages with prefix {prefix}", pids.len());

    let started = Instant::now();
    let mut failure: Option<String> = None;
    let mut stop_sent_at: Option<Instant> = None;
    while running.iter().any(|&r| r) {
        let wait = match (stop_sent_at, options.timeout) {
            (Some(at), _) => Duration::from_secs(10).saturating_sub(at.elapsed()),
            (None, Some(limit)) => limit.saturating_sub(started.elapsed()),
            (None, None) => Duration::from_secs(3600),
        };
        match receiver.recv_timeout(wait) {
            Ok(Event::Exited(index, status)) => {
                running[index] = false;
                let ok = matches!(&status, Ok(s) if s.success());
                if !ok && failure.is_none() {
                    let how = match status {
                        Ok(s) => s.to_string(),
                        Err(e) => e.to_string(),
                    };
                    failure = Some(format!("stage {} failed ({how})", STAGES[index]));
                    signal_all(&pids, &running, Signal::SIGTERM);
                    stop_sent_at.get_or_insert_with(Instant::now);
                }
            }
            Ok(Event::Signal) => {
                failure.get_or_insert_with(|| "interrupted".into());
                signal_all(&pids, &running, Signal::SIGTERM);
                stop_sent_at.get_or_insert_with(Instant::now);
            }
            Err(_) => {
                if stop_sent_at.is_some() {
                    // Grace period over.
                    signal_all(&pids, &running, Signal::SIGKILL);
                } else {
                    failure.get_or_insert_with(|| "timed out".into());
                    signal_all(&pids, &running, Signal::SIGTERM);
                    stop_sent_at = Some(Instant::now());
                }
            }
        }
    }
    // A live instance's files may belong to an outside producer still running; iceoryx2's
    // dead-node cleanup (at the next node's creation) removes those of crashed processes.
    if !options.live() {
        remove_leftovers(&prefix);
    }
    if let Some(failure) = failure {
        bail!("{failure}; all stages stopped");
    }
    Ok(config_path)
}

/// Removes shared-memory and iceoryx2 files of this run's prefix that a killed stage may have
/// left (a clean run leaves none).
fn remove_leftovers(prefix: &str) {
    let mut removed = 0;
    for dir in [
        "/dev/shm",
        "/tmp/iceoryx2",
        "/tmp/iceoryx2/services",
        "/tmp/iceoryx2/nodes",
    ] {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                if let Ok(inner) = std::fs::read_dir(&path) {
                    for file in inner.flatten() {
                        if file.file_name().to_string_lossy().starts_with(prefix)
                            && std::fs::remove_file(file.path()).is_ok()
                        {
                            removed += 1;
                        }
                    }
                }
            } else if entry.file_name().to_string_lossy().starts_with(prefix)
                && std::fs::remove_file(&path).is_ok()
            {
                removed += 1;
            }
        }
    }
    if removed > 0 {
        tracing::debug!("removed {removed} leftover shared-memory files of {prefix}");
    }
}
