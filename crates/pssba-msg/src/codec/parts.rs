//! Messages of any size over samples of a fixed size. A factor block or a window result of
//! `total_words` words travels as `ceil(total_words / sample_words)` samples (at least one),
//! each with the whole message header and a [`Parts`] saying where its words go. Samples of a
//! service arrive in the order they were sent (one publisher, lossless), so a receiver appends
//! parts as they come ([`Reassembly`]); a one-part message is decoded straight from its
//! sample, without a copy.

use crate::error::MsgError;
use crate::internal::types::{BlockHeader, Parts, ResultHeader};
use std::ops::Range;

const MESSAGE: &str = "message part";

/// Headers that carry a [`Parts`].
pub trait HasParts: Copy {
    /// This sample's place in its message.
    fn parts(&self) -> Parts;
    /// Sets it.
    fn set_parts(&mut self, parts: Parts);
}

impl HasParts for BlockHeader {
    fn parts(&self) -> Parts {
        self.parts
    }
    fn set_parts(&mut self, parts: Parts) {
        self.parts = parts;
    }
}

impl HasParts for ResultHeader {
    fn parts(&self) -> Parts {
        self.parts
    }
    fn set_parts(&mut self, parts: Parts) {
        self.parts = parts;
    }
}

/// The samples of message `message_id`: each one's [`Parts`] and range of words.
pub fn split(
    message_id: u64,
    total_words: usize,
    sample_words: usize,
) -> impl Iterator<Item = (Parts, Range<usize>)> {
    let sample_words = sample_words.max(1);
    let count = total_words.div_ceil(sample_words).max(1);
    (0..count).map(move |index| {
        let start = index * sample_words;
        let end = (start + sample_words).min(total_words);
        (
            Parts {
                message_id,
                index: index as u32,
                count: count as u32,
                offset_words: start as u64,
                total_words: total_words as u64,
            },
            start..end,
        )
    })
}

fn refuse(field: &'static str, value: u64, index: u64) -> MsgError {
    MsgError::OutOfRange {
        message: MESSAGE,
        field,
        value: value as f64,
        index,
    }
}

/// Appends the parts of one message at a time. Nothing is allocated from what a header
/// claims: the buffer grows by the words that actually arrived, so a header claiming 10^12
/// words costs nothing until the words come (and `max_words` refuses it up front). The
/// buffer is kept from one message to the next (no fresh pages for every block).
#[derive(Debug, Default)]
pub struct Reassembly {
    current: Option<Parts>,
    words: Vec<f64>,
}

impl Reassembly {
    /// Takes the next sample. Returns the whole message's words once its last part is in.
    /// A part out of order, of another message before the current one is complete (except
    /// the first part of a new message, which replaces it), or whose words do not add up is
    /// refused, and the incomplete message is dropped.
    pub fn push(
        &mut self,
        parts: Parts,
        payload: &[f64],
        max_words: u64,
    ) -> Result<Option<&[f64]>, MsgError> {
        match self.accept(parts, payload, max_words) {
            Ok(true) => Ok(Some(&self.words)),
            Ok(false) => Ok(None),
            Err(error) => {
                self.current = None;
                self.words.clear();
                Err(error)
            }
        }
    }

    /// True when the message is complete.
    fn accept(&mut self, parts: Parts, payload: &[f64], max_words: u64) -> Result<bool, MsgError> {
        if parts.count == 0 || parts.index >= parts.count {
            return Err(refuse(
                "index",
                u64::from(parts.index),
                u64::from(parts.count),
            ));
        }
        if parts.total_words > max_words {
            return Err(MsgError::TooLarge {
                message: MESSAGE,
                field: "total_words",
                value: parts.total_words,
                limit: max_words,
            });
        }
        match self.current {
            None if parts.index != 0 => {
                return Err(refuse("index", u64::from(parts.index), parts.message_id));
            }
            None => {
                self.current = Some(parts);
                self.words.clear();
            }
            // The first part of another message: the incomplete one's producer died (a
            // restarted stage sends its messages afresh), so it is abandoned.
            Some(current) if parts.index == 0 && parts.message_id != current.message_id => {
                self.current = Some(parts);
                self.words.clear();
            }
            Some(current) => {
                let expected = current.index + 1;
                if parts.message_id != current.message_id
                    || parts.count != current.count
                    || parts.total_words != current.total_words
                    || parts.index != expected
                {
                    return Err(refuse("index", u64::from(parts.index), parts.message_id));
                }
                self.current = Some(parts);
            }
        }
        if parts.offset_words != self.words.len() as u64 {
            return Err(refuse("offset_words", parts.offset_words, parts.message_id));
        }
        let end = self.words.len() as u64 + payload.len() as u64;
        if end > parts.total_words {
            return Err(refuse("total_words", parts.total_words, parts.message_id));
        }
        self.words.extend_from_slice(payload);
        if parts.index + 1 < parts.count {
            return Ok(false);
        }
        if end != parts.total_words {
            return Err(MsgError::LengthMismatch {
                message: MESSAGE,
                expected: parts.total_words,
                actual: end,
            });
        }
        self.current = None;
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_then_reassemble_gives_the_words_back() {
        for (total, sample) in [(0, 4), (1, 4), (4, 4), (5, 4), (17, 4), (1000, 1)] {
            let words: Vec<f64> = (0..total).map(|k| k as f64).collect();
            let mut reassembly = Reassembly::default();
            let mut done = None;
            let plan: Vec<_> = split(3, total, sample).collect();
            assert_eq!(plan.len(), total.div_ceil(sample).max(1));
            for (parts, range) in plan {
                assert!(done.is_none(), "complete before the last part");
                done = reassembly
                    .push(parts, &words[range], 1 << 20)
                    .expect("in order")
                    .map(<[f64]>::to_vec);
            }
            assert_eq!(done.expect("complete"), words);
        }
    }

    #[test]
    fn parts_out_of_order_or_lying_are_refused() {
        let words: Vec<f64> = (0..10).map(f64::from).collect();
        let plan: Vec<_> = split(0, 10, 4).collect();
        let mut r = Reassembly::default();
        // The second part first.
        assert!(r.push(plan[1].0, &words[plan[1].1.clone()], 100).is_err());
        // A part repeated.
        let mut r = Reassembly::default();
        assert!(
            r.push(plan[0].0, &words[0..4], 100)
                .expect("first")
                .is_none()
        );
        assert!(r.push(plan[0].0, &words[0..4], 100).is_err());
        // More words than the total claims.
        let mut r = Reassembly::default();
        let mut lying = plan[0].0;
        lying.total_words = 3;
        lying.count = 1;
        assert!(r.push(lying, &words[0..4], 100).is_err());
        // A claim above the bound, without allocating it.
        let mut huge = plan[0].0;
        huge.total_words = 1 << 40;
        assert!(matches!(
            r.push(huge, &words[0..4], 1 << 30),
            Err(MsgError::TooLarge { .. })
        ));
        // After a refusal, a whole new message goes through.
        for (parts, range) in split(1, 10, 4) {
            if let Some(done) = r.push(parts, &words[range], 100).expect("fresh message") {
                assert_eq!(done, words);
            }
        }
        // A new message's first part replaces an incomplete one (its producer restarted).
        let mut r = Reassembly::default();
        assert!(
            r.push(plan[0].0, &words[0..4], 100)
                .expect("first")
                .is_none()
        );
        let mut whole = None;
        for (parts, range) in split(7, 10, 4) {
            whole = r
                .push(parts, &words[range], 100)
                .expect("the new message")
                .map(<[f64]>::to_vec);
        }
        assert_eq!(whole.as_deref(), Some(&words[..]));
        // A last part that leaves a gap.
        let mut r = Reassembly::default();
        let mut short = plan[0].0;
        short.count = 1;
        assert!(matches!(
            r.push(short, &words[0..4], 100),
            Err(MsgError::LengthMismatch { .. })
        ));
    }
}
