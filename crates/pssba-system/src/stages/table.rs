//! The stage table: each stage's name, start order, arguments, restart policy and
//! subscriptions, declared once. The launcher builds a stage's command line from it
//! ([`StageArgs::for_launch`], [`StageArgs::argv`]); `pssba stage NAME` checks the arguments
//! against it ([`StageArgs::check`]) before [`crate::stages::run_stage`] runs the stage; the
//! restart policy ([`crate::supervision::restart::policy`]) reads it.

use crate::stages::{adjust, ingest, record, smooth};
use crate::supervision::restart::Restart;
use pssba_config::Config;
use pssba_msg::Stage;
use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// An argument a stage may take besides `--prefix` and `--config`, which every stage takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StageArg {
    /// `--out FILE`: the output MCAP file.
    Out,
    /// `--live`: frames come from an outside producer (`pssba run --input live`).
    Live,
    /// `--progress FILE`: where the stage keeps what a restarted process resumes from.
    Progress,
    /// `--source input:{JSON}`: the frame source.
    Source,
    /// `--rate HZ`: the publish rate.
    Rate,
}

impl StageArg {
    /// The flag on the command line.
    pub fn flag(self) -> &'static str {
        match self {
            StageArg::Out => "--out",
            StageArg::Live => "--live",
            StageArg::Progress => "--progress",
            StageArg::Source => "--source",
            StageArg::Rate => "--rate",
        }
    }
}

/// One row of the stage table.
#[derive(Debug, Clone, Copy)]
pub struct StageSpec {
    pub stage: Stage,
    /// What the stage does (one line).
    pub about: &'static str,
    /// The arguments it takes besides `--prefix` and `--config`.
    pub args: &'static [StageArg],
    /// Those of `args` it cannot run without.
    pub required: &'static [StageArg],
    /// What the launcher does when it crashes, and why.
    pub restart: (Restart, &'static str),
    /// What changes with live input (an outside producer, which cannot send frames again).
    pub live: Live,
    /// Its entry point: options from the (checked) arguments and the config, then its `run`.
    pub main: fn(StageArgs, Config) -> crate::Result<()>,
}

/// A stage's part in a run on live input.
#[derive(Debug, Clone, Copy)]
pub enum Live {
    /// It runs and is restarted as on files.
    AsOnFiles,
    /// It runs, with this restart policy and reason.
    Restart(Restart, &'static str),
    /// It does not run (the frames come from outside).
    NotRun,
}

impl StageSpec {
    /// True if the stage takes `arg`.
    pub fn takes(&self, arg: StageArg) -> bool {
        self.args.contains(&arg)
    }

    /// The shared-memory services it subscribes to (their subscriber counts come from here).
    pub fn subscriptions(&self) -> impl Iterator<Item = &'static str> {
        pssba_msg::internal::services::subscriptions_of(self.stage)
    }
}

/// The stages in start order: consumers first, so that no producer waits for a subscriber
/// that is not started yet.
pub const STAGES: [StageSpec; 4] = [
    StageSpec {
        stage: Stage::Record,
        about: "writes frames, poses and window results to MCAP",
        args: &[StageArg::Out, StageArg::Live, StageArg::Progress],
        required: &[StageArg::Out],
        restart: (
            Restart::OnCrash,
            "it ends the part it was writing at the last flush (its journal) and goes on in a \
             new part; the ingest stage sends the frames after that point again, the smooth \
             stage the windows",
        ),
        live: Live::Restart(
            Restart::Never,
            "with live input the frames it had not written are gone with it (an outside \
             producer cannot send them again)",
        ),
        main: record::main,
    },
    StageSpec {
        stage: Stage::Adjust,
        about: "solves each factor block (Levenberg-Marquardt)",
        args: &[],
        required: &[],
        restart: (
            Restart::OnCrash,
            "it keeps nothing between factor blocks; the smooth stage sends the pending block \
             again",
        ),
        live: Live::AsOnFiles,
        main: adjust::main,
    },
    StageSpec {
        stage: Stage::Smooth,
        about: "cuts sliding windows and extracts their smoothing kernels",
        args: &[StageArg::Live, StageArg::Progress],
        required: &[],
        restart: (
            Restart::OnCrash,
            "it goes on after the last window it published (its progress file); the ingest \
             stage sends the open window's frames again",
        ),
        live: Live::Restart(
            Restart::Never,
            "with live input the open window's frames are gone with it (an outside producer \
             cannot send them again)",
        ),
        main: smooth::main,
    },
    StageSpec {
        stage: Stage::Ingest,
        about: "publishes the input's frames",
        args: &[StageArg::Source, StageArg::Progress, StageArg::Rate],
        required: &[StageArg::Source],
        restart: (
            Restart::OnCrash,
            "it resumes after the last frame it published (its progress file)",
        ),
        live: Live::NotRun,
        main: ingest::main,
    },
];

/// The row of `stage`.
pub fn spec(stage: Stage) -> &'static StageSpec {
    &STAGES[start_index(stage)]
}

/// Position of `stage` in [`STAGES`].
pub fn start_index(stage: Stage) -> usize {
    STAGES
        .iter()
        .position(|s| s.stage == stage)
        .unwrap_or_else(|| unreachable!("every Stage has a row"))
}

/// A stage's arguments: what the launcher passes and `pssba stage NAME` parses.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StageArgs {
    /// iceoryx2 prefix of the run.
    pub prefix: String,
    /// The run's TOML config.
    pub config: Option<PathBuf>,
    pub out: Option<PathBuf>,
    pub live: bool,
    pub progress: Option<PathBuf>,
    pub source: Option<String>,
    pub rate_hz: Option<f64>,
}

/// What the launcher knows that a stage's arguments come from.
#[derive(Debug)]
pub struct LaunchContext<'a> {
    pub prefix: &'a str,
    pub config: &'a Path,
    pub out: &'a Path,
    pub live: bool,
    pub source: String,
    pub rate_hz: Option<f64>,
}

/// Where `stage` keeps its progress for a restart ([`crate::resume::progress`]), beside the
/// run's output `out`.
pub fn progress_path(out: &Path, stage: Stage) -> PathBuf {
    out.with_extension(format!("{stage}-progress"))
}

impl StageArgs {
    /// The arguments the launcher gives `spec`'s stage: each argument the stage takes, filled
    /// from the run (a progress file only when frames can be sent again, i.e. not live).
    pub fn for_launch(spec: &StageSpec, run: &LaunchContext<'_>) -> Self {
        Self {
            prefix: run.prefix.to_string(),
            config: Some(run.config.to_path_buf()),
            out: spec.takes(StageArg::Out).then(|| run.out.to_path_buf()),
            live: spec.takes(StageArg::Live) && run.live,
            progress: (spec.takes(StageArg::Progress) && !run.live)
                .then(|| progress_path(run.out, spec.stage)),
            source: spec.takes(StageArg::Source).then(|| run.source.clone()),
            rate_hz: run.rate_hz.filter(|_| spec.takes(StageArg::Rate)),
        }
    }

    /// True if `arg` is given.
    fn given(&self, arg: StageArg) -> bool {
        match arg {
            StageArg::Out => self.out.is_some(),
            StageArg::Live => self.live,
            StageArg::Progress => self.progress.is_some(),
            StageArg::Source => self.source.is_some(),
            StageArg::Rate => self.rate_hz.is_some(),
        }
    }

    /// Refuses an argument `stage` does not take or a required one missing, naming the flag.
    pub fn check(&self, stage: Stage) -> Result<(), String> {
        let spec = spec(stage);
        let all = [
            StageArg::Out,
            StageArg::Live,
            StageArg::Progress,
            StageArg::Source,
            StageArg::Rate,
        ];
        if let Some(extra) = all.iter().find(|a| self.given(**a) && !spec.takes(**a)) {
            return Err(format!("stage {stage} takes no {}", extra.flag()));
        }
        if let Some(missing) = spec.required.iter().find(|a| !self.given(**a)) {
            return Err(format!("stage {stage} needs {}", missing.flag()));
        }
        Ok(())
    }

    /// The command line after `stage NAME`.
    pub fn argv(&self) -> Vec<OsString> {
        let mut argv: Vec<OsString> = vec!["--prefix".into(), self.prefix.clone().into()];
        let mut push = |flag: &str, value: OsString| {
            argv.push(flag.into());
            argv.push(value);
        };
        if let Some(config) = &self.config {
            push("--config", config.into());
        }
        if let Some(out) = &self.out {
            push(StageArg::Out.flag(), out.into());
        }
        if let Some(progress) = &self.progress {
            push(StageArg::Progress.flag(), progress.into());
        }
        if let Some(source) = &self.source {
            push(StageArg::Source.flag(), source.into());
        }
        if let Some(rate) = self.rate_hz {
            push(StageArg::Rate.flag(), rate.to_string().into());
        }
        if self.live {
            argv.push(StageArg::Live.flag().into());
        }
        argv
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_stage_has_one_row_and_its_required_arguments_are_among_its_arguments() {
        for stage in Stage::ALL {
            assert_eq!(STAGES.iter().filter(|s| s.stage == stage).count(), 1);
            let spec = spec(stage);
            assert!(spec.required.iter().all(|a| spec.takes(*a)), "{stage}");
        }
    }

    #[test]
    fn launch_arguments_pass_the_stage_s_own_check_live_and_not() {
        for live in [false, true] {
            let run = LaunchContext {
                prefix: "p-",
                config: Path::new("run.config.toml"),
                out: Path::new("run.mcap"),
                live,
                source: "input:{}".into(),
                rate_hz: Some(10.0),
            };
            for spec in &STAGES {
                let args = StageArgs::for_launch(spec, &run);
                assert_eq!(args.check(spec.stage), Ok(()), "{} live {live}", spec.stage);
                assert_eq!(
                    args.progress.is_some(),
                    spec.takes(StageArg::Progress) && !live
                );
            }
        }
    }

    #[test]
    fn arguments_a_stage_does_not_take_or_needs_are_named() {
        let args = StageArgs {
            out: Some("x.mcap".into()),
            ..StageArgs::default()
        };
        assert_eq!(
            args.check(Stage::Adjust),
            Err("stage adjust takes no --out".into())
        );
        assert_eq!(
            StageArgs::default().check(Stage::Record),
            Err("stage record needs --out".into())
        );
        assert_eq!(
            StageArgs::default().check(Stage::Ingest),
            Err("stage ingest needs --source".into())
        );
    }
}
