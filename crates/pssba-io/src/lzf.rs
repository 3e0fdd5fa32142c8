//! A small LZF codec (the compression used by PCD `binary_compressed`).
//!
//! Format: a sequence of chunks, each starting with a control byte `ctrl`.
//! * `ctrl < 32`: a literal run; the next `ctrl + 1` bytes are copied as-is.
//! * otherwise a back-reference: length `(ctrl >> 5) + 2`, where a length
//!   field of 7 is extended by the following byte; the next byte is the low
//!   part of the offset, and the source starts
//!   `((ctrl & 0x1f) << 8) + low + 1` bytes before the current output end.
//!   Source and destination may overlap (byte-by-byte copy).

/// Largest back-reference distance the format can express.
pub const MAX_OFFSET: usize = 1 << 13;
/// Longest back-reference the format can express.
pub const MAX_MATCH: usize = 7 + 255 + 2;
const MAX_LITERAL: usize = 32;
const HASH_BITS: u32 = 14;
/// Upper bound on the expansion ratio of valid LZF data (3 input bytes → 264 output bytes).
const MAX_RATIO: usize = 88;

/// Why a byte stream is not valid LZF data of the expected size.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LzfError {
    /// The input ends in the middle of a chunk.
    #[error("input truncated at byte {at} (chunk needs {needed} more bytes)")]
    Truncated {
        /// Input position of the incomplete chunk.
        at: usize,
        /// Bytes the chunk still needed.
        needed: usize,
    },
    /// A back-reference points before the start of the output.
    #[error(
        "back-reference at input byte {at} reaches {distance} bytes back but only {available} bytes were decoded"
    )]
    BadOffset {
        /// Input position of the control byte.
        at: usize,
        /// Distance of the reference.
        distance: usize,
        /// Output length at that point.
        available: usize,
    },
    /// The data decodes to more or fewer bytes than expected.
    #[error("decoded size does not match the expected {expected} bytes (got {got}{})", if *.overflow { " or more" } else { "" })]
    SizeMismatch {
        /// Expected output length.
        expected: usize,
        /// Output length reached.
        got: usize,
        /// True when decoding stopped because it would exceed `expected`.
        overflow: bool,
    },
}

/// Decompresses `input`, which must decode to exactly `expected_len` bytes.
///
/// Never panics: corrupt input yields an [`LzfError`].
pub fn decompress(input: &[u8], expected_len: usize) -> Result<Vec<u8>, LzfError> {
    let cap = expected_len.min(input.len().saturating_mul(MAX_RATIO));
    let mut out: Vec<u8> = Vec::with_capacity(cap);
    let mut i = 0;
    while i < input.len() {
        let at = i;
        let ctrl = usize::from(input[i]);
        i += 1;
        if ctrl < 32 {
            let len = ctrl + 1;
            let lit = input.get(i..i + len).ok_or_else(|| LzfError::Truncated {
                at,
                needed: i + len - input.len(),
            })?;
            check_room(&out, len, expected_len)?;
            out.extend_from_slice(lit);
            i += len;
            continue;
        }
        let mut len = ctrl >> 5;
        let header_len = if len == 7 { 2 } else { 1 };
        let extra = input
            .get(i..i + header_len)
            .ok_or_else(|| LzfError::Truncated {
                at,
                needed: i + header_len - input.len(),
            })?;
        let low = if len == 7 {
            len += usize::from(extra[0]);
            extra[1]
        } else {
            extra[0]
        };
        i += header_len;
        let len = len + 2;
        let distance = ((ctrl & 0x1f) << 8) + usize::from(low) + 1;
        if distance > out.len() {
            return Err(LzfError::BadOffset {
                at,
                distance,
                available: out.len(),
            });
        }
        check_room(&out, len, expected_len)?;
        let start = out.len() - distance;
        for k in 0..len {
            let b = out[start + k];
            out.push(b);
        }
    }
    if out.len() != expected_len {
        return Err(LzfError::SizeMismatch {
            expected: expected_len,
            got: out.len(),
            overflow: false,
        });
    }
    Ok(out)
}

fn check_room(out: &[u8], len: usize, expected_len: usize) -> Result<(), LzfError> {
    if out.len() + len > expected_len {
        return Err(LzfError::SizeMismatch {
            expected: expected_len,
            got: out.len() + len,
            overflow: true,
        });
    }
    Ok(())
}

fn hash3(b: &[u8]) -> usize {
    let v = u32::from(b[0]) << 16 | u32::from(b[1]) << 8 | u32::from(b[2]);
    (v.wrapping_mul(2_654_435_761) >> (32 - HASH_BITS)) as usize
}

fn flush_literals(out: &mut Vec<u8>, mut lit: &[u8]) {
    while !lit.is_empty() {
        let n = lit.len().min(MAX_LITERAL);
        // n is in 1..=32, so n - 1 fits a control byte below 32.
        out.push((n - 1) as u8);
        out.extend_from_slice(&lit[..n]);
        lit = &lit[n..];
    }
}

fn push_backref(out: &mut Vec<u8>, len: usize, distance: usize) {
    let off = distance - 1; // 0..MAX_OFFSET
    let l = len - 2; // 1..=262
    let hi = (off >> 8) as u8;
    if l < 7 {
        out.push(((l as u8) << 5) | hi);
    } else {
        out.push((7 << 5) | hi);
        out.push((l - 7) as u8);
    }
    out.push((off & 0xff) as u8);
}

/// Compresses `input` with a greedy hash-table matcher.
///
/// The output is at most `input.len() + input.len() / 32 + 1` bytes and
/// [`decompress`]es back to `input`.
pub fn compress(input: &[u8]) -> Vec<u8> {
    let n = input.len();
    let mut out = Vec::with_capacity(n + n / MAX_LITERAL + 1);
    let mut table = vec![usize::MAX; 1 << HASH_BITS];
    let mut lit_start = 0;
    let mut i = 0;
    while i + 3 <= n {
        let h = hash3(&input[i..]);
        let cand = table[h];
        table[h] = i;
        let usable = cand != usize::MAX
            && i - cand <= MAX_OFFSET
            && input[cand..cand + 3] == input[i..i + 3];
        if !usable {
            i += 1;
            continue;
        }
        let max_len = MAX_MATCH.min(n - i);
        let mut len = 3;
        while len < max_len && input[cand + len] == input[i + len] {
            len += 1;
        }
        flush_literals(&mut out, &input[lit_start..i]);
        push_backref(&mut out, len, i - cand);
        let end = i + len;
        for p in (i + 1)..end.min(n.saturating_sub(2)) {
            table[hash3(&input[p..])] = p;
        }
        i = end;
        lit_start = i;
    }
    flush_literals(&mut out, &input[lit_start..]);
    out
}
