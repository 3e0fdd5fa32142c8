//! A stage's progress, kept in a small file so that the stage, restarted after a crash, goes on
//! where it was (README, "When a stage dies"): u64 words, little-endian, preceded by their
//! count, rewritten in one `pwrite` after each step. A crashed process cannot cut one write in
//! half, and the page cache keeps the file after the process dies (no fsync: it has to
//! outlive the process, not the machine). The launcher names the files and removes them after
//! the run.

use crate::error::{Context, bail};
use std::io::Read;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

/// Most words a progress file holds (a smooth stage's anchors of a 10,000-frame overlap).
const MAX_WORDS: u64 = 1 << 17;

/// An open progress file.
#[derive(Debug)]
pub struct ProgressFile {
    file: std::fs::File,
    path: PathBuf,
}

impl ProgressFile {
    /// Opens (or creates) the file; returns what an earlier run of the stage stored there,
    /// or `None` if it is new or empty (the stage's first start).
    pub fn open(path: &Path, what: &str) -> crate::Result<(Self, Option<Vec<u64>>)> {
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .with_context(|| format!("opening the {what} progress file {}", path.display()))?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes)
            .with_context(|| format!("reading {}", path.display()))?;
        let words: Vec<u64> = bytes
            .chunks_exact(8)
            .map(|chunk| {
                let mut le = [0u8; 8];
                le.copy_from_slice(chunk);
                u64::from_le_bytes(le)
            })
            .collect();
        let stored = match words.split_first() {
            None => None,
            Some((&count, rest)) if count <= MAX_WORDS && rest.len() as u64 >= count => {
                Some(rest[..count as usize].to_vec())
            }
            Some((&count, rest)) => bail!(
                Data,
                "the {what} progress file {} claims {count} words and holds {}",
                path.display(),
                rest.len()
            ),
        };
        let path = path.to_path_buf();
        Ok((Self { file, path }, stored))
    }

    /// Replaces the stored words (a longer earlier content's tail is ignored on reading).
    pub fn store(&self, words: &[u64]) -> crate::Result<()> {
        if words.len() as u64 > MAX_WORDS {
            bail!(
                Data,
                "{} words of progress; at most {MAX_WORDS}",
                words.len()
            );
        }
        let bytes: Vec<u8> = std::iter::once(words.len() as u64)
            .chain(words.iter().copied())
            .flat_map(u64::to_le_bytes)
            .collect();
        self.file
            .write_all_at(&bytes, 0)
            .with_context(|| format!("updating {}", self.path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reopened_file_gives_back_what_was_stored_and_a_torn_one_is_an_error() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("stage.progress");
        let (file, stored) = ProgressFile::open(&path, "test").expect("new");
        assert_eq!(stored, None);
        file.store(&[1, 2, u64::MAX, 7]).expect("store");
        file.store(&[4, 5, 6]).expect("store a shorter one");
        drop(file);
        let (_, stored) = ProgressFile::open(&path, "test").expect("reopen");
        assert_eq!(stored, Some(vec![4, 5, 6]));
        std::fs::write(&path, [9u8; 16]).expect("write");
        let error = ProgressFile::open(&path, "test").expect_err("a count it does not hold");
        assert!(format!("{error:#}").contains("claims"), "{error:#}");
    }
}
