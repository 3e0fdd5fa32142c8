//! `pssba run`: starts the four stages as processes of the `pssba` binary (`pssba stage ...`),
//! gives the run its own iceoryx2 prefix, supervises them (a thread per child reports its
//! exit on a channel; no polling) and forwards Ctrl-C/SIGTERM. A stage that crashes is
//! restarted after a backoff when its policy allows ([`crate::supervision::restart`]); the new process
//! removes the dead one's ports with iceoryx2's dead-node cleanup. Otherwise, or past
//! `[system] max_restarts`, everything is stopped and the error names the stage.

use crate::Config;
use crate::error::{Context, bail};
use crate::source::SourceSpec;
use crate::stages::table::{
    LaunchContext, Live, STAGES, StageArg, StageArgs, StageSpec, progress_path, start_index,
};
use crate::supervision::restart::{self, Restart};
use crossbeam_channel::{Receiver, Sender, unbounded};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use pssba_msg::Stage;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

#[derive(Debug, Clone)]
pub struct LaunchOptions {
    /// The `pssba` executable whose `stage` subcommands are the stages.
    pub exe: PathBuf,
    /// Effective configuration (written next to the MCAP file and given to every stage).
    pub config: Config,
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

/// A prefix unique to this run (process id and clock), so runs never share services.
pub fn unique_prefix() -> String {
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    format!("pssba-{}-{nanos}-", std::process::id())
}

/// The command line of stage `spec` ([`crate::stages::table`]).
fn stage_command(
    options: &LaunchOptions,
    spec: &StageSpec,
    prefix: &str,
    config_path: &Path,
) -> Command {
    let run = LaunchContext {
        prefix,
        config: config_path,
        out: &options.out,
        live: options.live(),
        source: options.source.to_string(),
        rate_hz: options.rate_hz,
    };
    let mut command = Command::new(&options.exe);
    command
        .arg("stage")
        .arg(spec.stage.name())
        .args(StageArgs::for_launch(spec, &run).argv());
    for _ in 0..options.verbose {
        command.arg("-v");
    }
    command
}

enum Event {
    Exited(usize, std::io::Result<ExitStatus>),
    Signal,
}

/// What the launcher knows of one stage.
#[derive(Debug, Default, Clone, Copy)]
struct StageState {
    /// Its process, while it runs.
    pid: Option<u32>,
    /// Restarts so far.
    restarts: u32,
    /// When it is due to start again after a crash.
    restart_due: Option<Instant>,
    /// Stopped by the launcher because it has nothing left to do: its exit is not a failure.
    released: bool,
}

/// The files a run keeps beside its output for restarts (removed before and after the run).
fn restart_files(out: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = STAGES
        .iter()
        .filter(|spec| spec.takes(StageArg::Progress))
        .map(|spec| progress_path(out, spec.stage))
        .collect();
    files.push(crate::resume::record_journal::journal_path(&progress_path(
        out,
        Stage::Record,
    )));
    files
}

fn signal_all(stages: &[StageState], signal: Signal) {
    for pid in stages.iter().filter_map(|s| s.pid) {
        // The child may have exited in between; nothing to do then.
        let _ = kill(Pid::from_raw(pid as i32), signal);
    }
}

/// Starts stage `index`; a thread waits for it and reports its exit on `sender`.
fn spawn_stage(
    options: &LaunchOptions,
    index: usize,
    prefix: &str,
    config_path: &Path,
    sender: &Sender<Event>,
) -> crate::Result<u32> {
    let stage = STAGES[index].stage;
    let mut child: Child = stage_command(options, &STAGES[index], prefix, config_path)
        .spawn()
        .with_context(|| format!("starting stage {stage} ({})", options.exe.display()))?;
    let pid = child.id();
    let sender = sender.clone();
    std::thread::spawn(move || {
        let status = child.wait();
        let _ = sender.send(Event::Exited(index, status));
    });
    Ok(pid)
}

/// Removes what dead iceoryx2 nodes of `prefix` left (iceoryx2's own dead-node detection).
fn clean_dead_nodes(prefix: &str) {
    match pssba_msg::node::remove_dead_nodes(prefix) {
        Ok(0) => {}
        Ok(n) => tracing::info!("removed the iceoryx2 resources of {n} dead processes"),
        Err(error) => tracing::warn!("could not clean up dead iceoryx2 nodes: {error}"),
    }
}

/// Prepares the run's files: the output folder, the effective config (returned) and no
/// progress file left by an earlier run.
fn prepare_files(options: &LaunchOptions) -> crate::Result<PathBuf> {
    if let Some(parent) = options.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    let config_path = options.out.with_extension("config.toml");
    std::fs::write(&config_path, options.config.to_toml()?)
        .with_context(|| format!("writing {}", config_path.display()))?;
    // Further parts of an earlier recording to the same file would be read as this run's.
    let old_parts = pssba_recording::existing_parts(&options.out)
        .into_iter()
        .skip(1);
    for old in restart_files(&options.out).into_iter().chain(old_parts) {
        match std::fs::remove_file(&old) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => bail!(Run, "removing the old {}: {e}", old.display()),
        }
    }
    Ok(config_path)
}

/// The run's iceoryx2 prefix. A live instance has a fixed one that outside producers and
/// subscribers use; what an earlier crashed run left there is cleaned, and an instance that
/// another run's stages are attached to is refused.
fn run_prefix(source: &SourceSpec) -> crate::Result<String> {
    let SourceSpec::Live(instance) = source else {
        return Ok(unique_prefix());
    };
    let prefix = pssba_client::instance::prefix(instance);
    clean_dead_nodes(&prefix);
    let system: Vec<String> = pssba_msg::node::alive_node_names(&prefix)?
        .into_iter()
        .filter(|n| Stage::from_name(n).is_some())
        .collect();
    if !system.is_empty() {
        bail!(
            Usage,
            "live instance {instance} is in use: stages {} of another `pssba run` are \
             attached to it; stop that run or choose another --instance",
            system.join(", ")
        );
    }
    Ok(prefix)
}

/// Runs the system to completion. Returns the effective config path.
pub fn launch(options: &LaunchOptions) -> crate::Result<PathBuf> {
    let config_path = prepare_files(options)?;
    let prefix = run_prefix(&options.source)?;
    let (sender, receiver): (Sender<Event>, Receiver<Event>) = unbounded();
    let signal_sender = sender.clone();
    // Ctrl-C / SIGTERM: forward to the stages and let them finish the MCAP file.
    ctrlc::set_handler(move || {
        let _ = signal_sender.send(Event::Signal);
    })
    .context("installing the Ctrl-C handler")?;

    let mut supervisor = Supervisor {
        options,
        prefix: &prefix,
        config_path: &config_path,
        sender,
        stages: [StageState::default(); STAGES.len()],
        failure: None,
        stop_sent_at: None,
    };
    for (index, spec) in STAGES.iter().enumerate() {
        if matches!(spec.live, Live::NotRun) && options.live() {
            continue;
        }
        supervisor.start(index)?;
    }
    tracing::info!("started the stages with prefix {prefix}");
    let outcome = supervisor.run(&receiver);
    // What killed stages left (a clean run leaves nothing). On a live instance only dead
    // nodes go: an outside producer may still be attached.
    clean_dead_nodes(&prefix);
    if !options.live() {
        sweep_prefix_files(&prefix);
    }
    for file in restart_files(&options.out) {
        let _ = std::fs::remove_file(file);
    }
    outcome?;
    if let Some(failure) = supervisor.failure {
        bail!(Run, "{failure}; all stages stopped");
    }
    Ok(config_path)
}

/// The supervision loop's state.
struct Supervisor<'a> {
    options: &'a LaunchOptions,
    prefix: &'a str,
    config_path: &'a Path,
    sender: Sender<Event>,
    stages: [StageState; STAGES.len()],
    /// Why the run stops early, once it does.
    failure: Option<String>,
    /// When SIGTERM went to every stage.
    stop_sent_at: Option<Instant>,
}

impl Supervisor<'_> {
    fn start(&mut self, index: usize) -> crate::Result<()> {
        let pid = spawn_stage(
            self.options,
            index,
            self.prefix,
            self.config_path,
            &self.sender,
        )?;
        self.stages[index].pid = Some(pid);
        Ok(())
    }

    /// Stops every stage (SIGTERM, then SIGKILL after 10 s) for `failure`.
    fn stop(&mut self, failure: String) {
        self.failure.get_or_insert(failure);
        for state in &mut self.stages {
            state.restart_due = None;
        }
        signal_all(&self.stages, Signal::SIGTERM);
        self.stop_sent_at.get_or_insert_with(Instant::now);
    }

    /// Until every stage has exited.
    fn run(&mut self, receiver: &Receiver<Event>) -> crate::Result<()> {
        let started = Instant::now();
        while self
            .stages
            .iter()
            .any(|s| s.pid.is_some() || s.restart_due.is_some())
        {
            let wait = match (self.stop_sent_at, self.options.timeout) {
                (Some(at), _) => Duration::from_secs(10).saturating_sub(at.elapsed()),
                (None, Some(limit)) => limit.saturating_sub(started.elapsed()),
                (None, None) => Duration::from_secs(3600),
            };
            let next_restart = self.stages.iter().filter_map(|s| s.restart_due).min();
            let wait = next_restart.map_or(wait, |due| {
                wait.min(due.saturating_duration_since(Instant::now()))
            });
            match receiver.recv_timeout(wait) {
                Ok(Event::Exited(index, status)) => self.exited(index, status),
                Ok(Event::Signal) => self.stop("interrupted".into()),
                Err(_) => {
                    let now = Instant::now();
                    let due = self
                        .stages
                        .iter()
                        .position(|s| s.restart_due.is_some_and(|due| due <= now));
                    if let Some(index) = due {
                        // The new process removes the dead one's ports itself (`create_node`)
                        // before it attaches in their place: the stage's node never vanishes
                        // from the prefix in between, which the ingest stage relies on.
                        self.stages[index].restart_due = None;
                        self.start(index)?;
                        tracing::warn!(
                            "stage {} restarted (pid {})",
                            STAGES[index].stage,
                            self.stages[index].pid.unwrap_or_default()
                        );
                    } else if self.stop_sent_at.is_some() {
                        // Grace period over.
                        signal_all(&self.stages, Signal::SIGKILL);
                    } else if self
                        .options
                        .timeout
                        .is_some_and(|limit| started.elapsed() >= limit)
                    {
                        self.stop("timed out".into());
                    }
                }
            }
        }
        Ok(())
    }

    /// True once the smooth stage has exited successfully: every window is done and the
    /// adjust stage was told to shut down.
    fn smooth_finished(&self) -> bool {
        let smooth = start_index(Stage::Smooth);
        let state = &self.stages[smooth];
        state.pid.is_none() && state.restart_due.is_none() && self.failure.is_none()
    }

    /// The smooth stage finished, so no factor block will come. An adjust stage restarted
    /// after its predecessor received the shutdown block (or lost it with its queue) would
    /// wait for blocks for ever: a pending restart is dropped and a running restarted adjust
    /// stage is stopped. The first adjust stage shuts down by itself (it lingers until the
    /// recorder has its last pose set).
    fn release_adjust(&mut self) {
        let adjust = &mut self.stages[start_index(Stage::Adjust)];
        if adjust.restart_due.take().is_some() {
            tracing::info!("the smooth stage finished: the adjust stage is not restarted");
        }
        if let (Some(pid), true) = (adjust.pid, adjust.restarts > 0) {
            adjust.released = true;
            tracing::info!(
                "the smooth stage finished: stopping the restarted adjust stage (pid {pid}), \
                 which will receive no block"
            );
            // SIGKILL, not SIGTERM (which it would report as an interruption): nothing is in
            // flight, since the smooth stage leaves only after the recorder has, and the
            // launcher cleans the dead node's resources at the end.
            let _ = kill(Pid::from_raw(pid as i32), Signal::SIGKILL);
        }
    }

    /// A stage exited: fine, restarted after a backoff, or the run stops.
    fn exited(&mut self, index: usize, status: std::io::Result<ExitStatus>) {
        let stage = STAGES[index].stage;
        let system = &self.options.config.system;
        let state = &mut self.stages[index];
        state.pid = None;
        if state.released || self.failure.is_some() {
            return;
        }
        if matches!(&status, Ok(s) if s.success()) {
            if stage == Stage::Smooth {
                self.release_adjust();
            }
            return;
        }
        let how = match &status {
            Ok(s) => s.to_string(),
            Err(e) => e.to_string(),
        };
        let crash = matches!(&status, Ok(s) if restart::crashed(s));
        if crash && stage == Stage::Adjust && self.smooth_finished() {
            tracing::warn!(
                "stage adjust crashed ({how}) after the smooth stage finished: every factor \
                 block was answered, so it is not restarted"
            );
            return;
        }
        let state = &mut self.stages[index];
        let (policy, why) = restart::policy(stage, self.options.live());
        if crash && policy == Restart::OnCrash && state.restarts < system.max_restarts {
            state.restarts += 1;
            let backoff = system.restart_backoff(state.restarts);
            tracing::warn!(
                "stage {stage} crashed ({how}); restart {} of {} in {:.1} s: {why}",
                state.restarts,
                system.max_restarts,
                backoff.as_secs_f64()
            );
            state.restart_due = Some(Instant::now() + backoff);
            return;
        }
        let reason = match (crash, policy) {
            (false, _) => String::new(),
            (true, Restart::Never) => format!("; it is not restarted: {why}"),
            (true, Restart::OnCrash) => {
                format!("; not restarted again after {} restarts", state.restarts)
            }
        };
        self.stop(format!("stage {stage} failed ({how}){reason}"));
    }
}

/// Removes the files left under a run's own prefix once every stage has exited and the dead
/// nodes are cleaned: iceoryx2 0.10 keeps a per-prefix `global_mgmt` segment in /dev/shm
/// after its last node is gone. Only for a prefix unique to this run.
fn sweep_prefix_files(prefix: &str) {
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
