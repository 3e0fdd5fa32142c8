//! Instances: `pssba run --input live --instance NAME` and the outside processes that feed or
//! read it meet under one name (docs/interface.md).

use crate::error::ServiceError;

/// The instance of a run the launcher starts on files (under a prefix unique to the run).
pub const RUN: &str = "run";

const LIVE_PREFIX: &str = "pssba-live-";

/// Checks an instance name: 1 to 64 of letters, digits, `-` and `_`.
pub fn check(instance: &str) -> Result<(), ServiceError> {
    let ok = (1..=64).contains(&instance.len())
        && instance
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
    if ok {
        Ok(())
    } else {
        Err(ServiceError {
            what: format!("instance '{instance}'"),
            reason: "use 1 to 64 letters, digits, '-' or '_'".into(),
        })
    }
}

/// The iceoryx2 prefix of every node of a live instance: `pssba-live-NAME-`.
pub fn prefix(instance: &str) -> String {
    format!("{LIVE_PREFIX}{instance}-")
}

/// The instance whose prefix is `prefix`, if it is a live instance's.
pub fn from_prefix(prefix: &str) -> Option<&str> {
    prefix
        .strip_prefix(LIVE_PREFIX)?
        .strip_suffix('-')
        .filter(|name| check(name).is_ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefix_round_trips() {
        assert_eq!(from_prefix(&prefix("uav-1")), Some("uav-1"));
        assert_eq!(from_prefix("pssba-123-456-"), None);
        assert_eq!(from_prefix("pssba-live--"), None);
        assert!(check("a/b").is_err());
        assert!(check(&"x".repeat(65)).is_err());
        assert!(check("drone_7").is_ok());
    }
}
