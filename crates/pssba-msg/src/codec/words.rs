//! Checked reading of f64 payload words: counts, finiteness, integer indices.

use crate::error::MsgError;

/// `count * words_each`, refusing counts above `limit` and overflow.
pub fn checked_words(
    message: &'static str,
    field: &'static str,
    count: u64,
    words_each: usize,
    limit: u64,
) -> Result<u64, MsgError> {
    if count > limit {
        return Err(MsgError::TooLarge {
            message,
            field,
            value: count,
            limit,
        });
    }
    count
        .checked_mul(words_each as u64)
        .ok_or(MsgError::TooLarge {
            message,
            field,
            value: count,
            limit,
        })
}

/// Sums word counts with an overflow check, then compares with the payload length.
pub fn expect_len(message: &'static str, parts: &[u64], actual: usize) -> Result<(), MsgError> {
    let expected = parts
        .iter()
        .try_fold(0u64, |acc, &p| acc.checked_add(p))
        .ok_or(MsgError::TooLarge {
            message,
            field: "payload",
            value: u64::MAX,
            limit: u64::MAX,
        })?;
    if expected != actual as u64 {
        return Err(MsgError::LengthMismatch {
            message,
            expected,
            actual: actual as u64,
        });
    }
    Ok(())
}

/// Sequential reader over payload words that reports which item a bad value came from.
#[derive(Debug)]
pub struct WordReader<'a> {
    message: &'static str,
    words: &'a [f64],
    position: usize,
}

impl<'a> WordReader<'a> {
    /// Reads `words` of a `message`.
    pub fn new(message: &'static str, words: &'a [f64]) -> Self {
        Self {
            message,
            words,
            position: 0,
        }
    }

    /// The next `n` words, all finite. Lengths were checked up front, so running out is
    /// reported as a length mismatch rather than a panic.
    pub fn finite(
        &mut self,
        n: usize,
        field: &'static str,
        index: u64,
    ) -> Result<&'a [f64], MsgError> {
        let end = self.position + n;
        let Some(slice) = self.words.get(self.position..end) else {
            return Err(MsgError::LengthMismatch {
                message: self.message,
                expected: end as u64,
                actual: self.words.len() as u64,
            });
        };
        self.position = end;
        if slice.iter().all(|v| v.is_finite()) {
            Ok(slice)
        } else {
            Err(MsgError::NotFinite {
                message: self.message,
                field,
                index,
            })
        }
    }

    /// The next word, allowed to be NaN or infinite (diagnostic values).
    pub fn any(&mut self) -> Result<f64, MsgError> {
        let value = self
            .words
            .get(self.position)
            .copied()
            .ok_or(MsgError::LengthMismatch {
                message: self.message,
                expected: self.position as u64 + 1,
                actual: self.words.len() as u64,
            })?;
        self.position += 1;
        Ok(value)
    }

    /// The next word as an integer in `0..bound`.
    pub fn index(&mut self, bound: u64, field: &'static str, index: u64) -> Result<u64, MsgError> {
        let value = self.finite(1, field, index)?[0];
        let as_int = value as u64;
        if value < 0.0 || value.fract() != 0.0 || as_int >= bound {
            return Err(MsgError::OutOfRange {
                message: self.message,
                field,
                value,
                index,
            });
        }
        Ok(as_int)
    }
}
