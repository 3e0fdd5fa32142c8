//! The process system's one error type. The libraries below it keep their own (`io`, the
//! config, the sources, the recording format, the messages, the core); this wraps them and adds
//! the system's own kinds, so callers can tell a shared-memory failure from bad data or a
//! stage that did not finish. The `pssba` binary turns it into an `anyhow::Error` to print.
//!
//! Messages read as anyhow's did: `{}` shows the outermost message, `{:#}` the whole chain
//! joined by `": "`, and [`std::error::Error::source`] walks the same chain.

use std::fmt;

/// What went wrong in a stage, the launcher or the resume state.
#[derive(Debug)]
pub enum Error {
    /// What the system was doing when `source` failed ("opening DIR", "reading frame 3").
    Context { what: String, source: Box<Error> },
    /// A file or a pipe (the error is the operating system's, with its own message).
    Io(std::io::Error),
    /// A JSON state or progress file that does not parse.
    Json(serde_json::Error),
    /// A config file or value (`pssba-config`).
    Config(Box<pssba_config::ConfigError>),
    /// An input that cannot be opened or read (`pssba-source`).
    Source(Box<pssba_source::SourceError>),
    /// The MCAP recording (`pssba-recording`).
    Recording(Box<pssba_recording::RecordingError>),
    /// A message that does not decode (`pssba-msg`).
    Message(Box<pssba_msg::MsgError>),
    /// A node, service or port that could not be created (`pssba-msg`).
    Service(Box<pssba_msg::ServiceError>),
    /// The frames protocol could not go on (`pssba-msg`, through pssba-client's ports).
    Frame(Box<pssba_msg::FrameError>),
    /// The adjustment refused its input (`pssba-core`).
    Core(Box<pssba_core::CoreError>),
    /// The Ctrl-C handler could not be installed.
    Signal(ctrlc::Error),
    /// Shared memory: a service, port, sample or wait set that iceoryx2 refused.
    Ipc(String),
    /// Data that arrived but cannot be used (an out-of-order frame, a journal that disagrees).
    Data(String),
    /// Arguments or settings that do not fit together (`--out` for a stage that takes none).
    Usage(String),
    /// A stage or run that did not finish (a child that exited, a producer that vanished).
    Run(String),
}

/// The system's results; the error defaults to [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Wraps `self` as the cause of `what`.
    pub fn context(self, what: impl fmt::Display) -> Error {
        Error::Context {
            what: what.to_string(),
            source: Box::new(self),
        }
    }

    /// A shared-memory failure: `what` followed by iceoryx2's error (its `Debug`, which names
    /// the variant).
    pub(crate) fn ipc<E: fmt::Debug>(what: &str) -> impl FnOnce(E) -> Error + '_ {
        move |e| Error::Ipc(format!("{what}: {e:?}"))
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Context { what, .. } => f.write_str(what)?,
            Error::Io(e) => fmt::Display::fmt(e, f)?,
            Error::Json(e) => fmt::Display::fmt(e, f)?,
            Error::Config(e) => fmt::Display::fmt(e, f)?,
            Error::Source(e) => fmt::Display::fmt(e, f)?,
            Error::Recording(e) => fmt::Display::fmt(e, f)?,
            Error::Message(e) => fmt::Display::fmt(e, f)?,
            Error::Service(e) => fmt::Display::fmt(e, f)?,
            Error::Frame(e) => fmt::Display::fmt(e, f)?,
            Error::Core(e) => fmt::Display::fmt(e, f)?,
            Error::Signal(e) => fmt::Display::fmt(e, f)?,
            Error::Ipc(m) | Error::Data(m) | Error::Usage(m) | Error::Run(m) => f.write_str(m)?,
        }
        if f.alternate() {
            let mut cause = std::error::Error::source(self);
            while let Some(e) = cause {
                write!(f, ": {e}")?;
                cause = e.source();
            }
        }
        Ok(())
    }
}

impl std::error::Error for Error {
    /// The next link of the chain. The wrapped library errors are transparent: their own
    /// message is this error's, so the chain goes on with their source.
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Context { source, .. } => Some(source.as_ref()),
            Error::Io(e) => e.source(),
            Error::Json(e) => e.source(),
            Error::Config(e) => e.source(),
            Error::Source(e) => e.source(),
            Error::Recording(e) => e.source(),
            Error::Message(e) => e.source(),
            Error::Service(e) => e.source(),
            Error::Frame(e) => e.source(),
            Error::Core(e) => e.source(),
            Error::Signal(e) => e.source(),
            Error::Ipc(_) | Error::Data(_) | Error::Usage(_) | Error::Run(_) => None,
        }
    }
}

macro_rules! wrap {
    ($($variant:ident($ty:ty)),* $(,)?) => {$(
        impl From<$ty> for Error {
            fn from(e: $ty) -> Error {
                Error::$variant(e.into())
            }
        }
    )*};
}
// The library errors are boxed in the enum (some are large), taken by value here.
wrap!(
    Io(std::io::Error),
    Json(serde_json::Error),
    Config(pssba_config::ConfigError),
    Source(pssba_source::SourceError),
    Recording(pssba_recording::RecordingError),
    Message(pssba_msg::MsgError),
    Service(pssba_msg::ServiceError),
    Frame(pssba_msg::FrameError),
    Core(pssba_core::CoreError),
    Signal(ctrlc::Error),
);

/// `.context(..)` and `.with_context(|| ..)` on results, as anyhow spells them.
pub(crate) trait Context<T> {
    fn context(self, what: impl fmt::Display) -> Result<T>;
    fn with_context<D: fmt::Display>(self, what: impl FnOnce() -> D) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn context(self, what: impl fmt::Display) -> Result<T> {
        self.map_err(|e| e.into().context(what))
    }

    fn with_context<D: fmt::Display>(self, what: impl FnOnce() -> D) -> Result<T> {
        self.map_err(|e| e.into().context(what()))
    }
}

/// `bail!(Kind, "format", args..)`: returns `Err(Error::Kind(message))`.
macro_rules! bail {
    ($kind:ident, $($message:tt)+) => {
        return Err($crate::Error::$kind(format!($($message)+)))
    };
}
pub(crate) use bail;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alternate_display_joins_the_chain_as_anyhow_did() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let e = Error::from(io)
            .context("reading state.json")
            .context("resuming smooth");
        assert_eq!(e.to_string(), "resuming smooth");
        assert_eq!(
            format!("{e:#}"),
            "resuming smooth: reading state.json: no such file"
        );
        let as_anyhow = anyhow::Error::from(e);
        assert_eq!(
            format!("{as_anyhow:#}"),
            "resuming smooth: reading state.json: no such file"
        );
    }

    #[test]
    fn bail_names_the_kind() {
        fn refuse(frame: u32) -> Result<()> {
            bail!(Data, "frame {frame} is older than the window");
        }
        let e = refuse(3).expect_err("bail! returns");
        assert!(matches!(e, Error::Data(_)));
        assert_eq!(e.to_string(), "frame 3 is older than the window");
    }
}
