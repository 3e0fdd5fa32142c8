//! Reading serialized ROS messages field by field, in either wire format:
//!
//! - **ROS 1**: little-endian, packed (no alignment); a string is a `u32` byte count and the
//!   bytes; a header starts with a `u32` sequence number.
//! - **CDR** (ROS 2): a 4-byte encapsulation header (`00 01` little-endian, `00 00` big-endian,
//!   then two option bytes), then each primitive aligned to its own size (at most 8) counted
//!   from the end of that header; a string's count includes its terminating NUL.
//!
//! Every read is bounds-checked: a short or corrupt message is a [`DecodeError`], never a
//! panic, and a sequence length is checked against the bytes left before anything is
//! allocated for it.

use std::fmt;

/// A message that cannot be decoded; the caller adds the file, topic and message index.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodeError(pub String);

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for DecodeError {}

/// Shorthand for building a [`DecodeError`].
pub fn decode_err(message: impl Into<String>) -> DecodeError {
    DecodeError(message.into())
}

/// The wire format of a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wire {
    /// ROS 1 serialization (bag v2.0 message data).
    Ros1,
    /// CDR, as ROS 2 writes it (rosbag2 sqlite3 or MCAP with message encoding `cdr`).
    Cdr,
}

/// A bounds-checked reader over one message's bytes.
#[derive(Debug, Clone)]
pub struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
    /// Alignment is counted from here (CDR: the end of the encapsulation header).
    origin: usize,
    little_endian: bool,
    wire: Wire,
}

impl<'a> Cursor<'a> {
    /// A cursor at the start of a message; for CDR, reads the encapsulation header.
    pub fn new(data: &'a [u8], wire: Wire) -> Result<Self, DecodeError> {
        match wire {
            Wire::Ros1 => Ok(Cursor {
                data,
                pos: 0,
                origin: 0,
                little_endian: true,
                wire,
            }),
            Wire::Cdr => {
                let header = data.get(..4).ok_or_else(|| {
                    decode_err(format!(
                        "{} bytes: too short for the 4-byte CDR encapsulation header",
                        data.len()
                    ))
                })?;
                let little_endian = match (header[0], header[1]) {
                    (0, 1) => true,
                    (0, 0) => false,
                    (a, b) => {
                        return Err(decode_err(format!(
                            "CDR encapsulation {a:#04x} {b:#04x} is not plain CDR \
                             (00 00 or 00 01); XCDR2 is not supported"
                        )));
                    }
                };
                Ok(Cursor {
                    data,
                    pos: 4,
                    origin: 4,
                    little_endian,
                    wire,
                })
            }
        }
    }

    /// The wire format.
    pub fn wire(&self) -> Wire {
        self.wire
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    /// Skips padding up to a multiple of `size` (CDR only).
    fn align(&mut self, size: usize) -> Result<(), DecodeError> {
        if self.wire == Wire::Cdr {
            let offset = (self.pos - self.origin) % size;
            if offset != 0 {
                self.take(size - offset, "padding")?;
            }
        }
        Ok(())
    }

    /// The next `n` raw bytes.
    pub fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], DecodeError> {
        if n > self.remaining() {
            return Err(decode_err(format!(
                "message ends inside {what}: needs {n} bytes at byte {}, {} left",
                self.pos,
                self.remaining()
            )));
        }
        let bytes = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(bytes)
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], DecodeError> {
        self.align(N)?;
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N, what)?);
        if !self.little_endian {
            out.reverse();
        }
        Ok(out)
    }

    /// A `uint8`.
    pub fn u8(&mut self, what: &str) -> Result<u8, DecodeError> {
        Ok(self.take(1, what)?[0])
    }

    /// A `bool` (any non-zero byte is true).
    pub fn bool(&mut self, what: &str) -> Result<bool, DecodeError> {
        Ok(self.u8(what)? != 0)
    }

    /// A `uint32`.
    pub fn u32(&mut self, what: &str) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }

    /// An `int32`.
    pub fn i32(&mut self, what: &str) -> Result<i32, DecodeError> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }

    /// A `uint64`.
    pub fn u64(&mut self, what: &str) -> Result<u64, DecodeError> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }

    /// A `float32`.
    pub fn f32(&mut self, what: &str) -> Result<f32, DecodeError> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }

    /// A `float64`.
    pub fn f64(&mut self, what: &str) -> Result<f64, DecodeError> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    /// A sequence length, checked against the bytes left: each element takes at least
    /// `min_element_bytes`, so a corrupt length fails here instead of allocating.
    pub fn sequence_len(
        &mut self,
        min_element_bytes: usize,
        what: &str,
    ) -> Result<usize, DecodeError> {
        let len = self.u32(what)? as usize;
        let needed = len.saturating_mul(min_element_bytes.max(1));
        if needed > self.remaining() {
            return Err(decode_err(format!(
                "{what} claims {len} elements ({needed} bytes at least) but {} bytes are left",
                self.remaining()
            )));
        }
        Ok(len)
    }

    /// A string (ROS 1: count then bytes; CDR: count including the NUL, then bytes and NUL).
    pub fn string(&mut self, what: &str) -> Result<String, DecodeError> {
        let len = self.sequence_len(1, what)?;
        let bytes = self.take(len, what)?;
        let text = match self.wire {
            Wire::Ros1 => bytes,
            Wire::Cdr => match bytes.split_last() {
                Some((0, text)) => text,
                _ if bytes.is_empty() => bytes,
                _ => return Err(decode_err(format!("{what}: CDR string without its NUL"))),
            },
        };
        String::from_utf8(text.to_vec()).map_err(|_| decode_err(format!("{what}: not UTF-8")))
    }

    /// A `std_msgs/Header`: the stamp in nanoseconds since the epoch, and the frame id.
    pub fn header(&mut self) -> Result<Header, DecodeError> {
        if self.wire == Wire::Ros1 {
            self.u32("header.seq")?;
        }
        let sec = match self.wire {
            Wire::Ros1 => i64::from(self.u32("header.stamp.sec")?),
            Wire::Cdr => i64::from(self.i32("header.stamp.sec")?),
        };
        let nsec = self.u32("header.stamp.nanosec")?;
        if nsec >= 1_000_000_000 {
            return Err(decode_err(format!(
                "header.stamp.nanosec is {nsec}, not below 1e9"
            )));
        }
        let frame_id = self.string("header.frame_id")?;
        Ok(Header {
            stamp_ns: sec * 1_000_000_000 + i64::from(nsec),
            frame_id,
        })
    }
}

/// The fields of `std_msgs/Header` that matter here.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    /// Stamp, nanoseconds since the epoch.
    pub stamp_ns: i64,
    /// The frame the message's data is expressed in.
    pub frame_id: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cdr_aligns_from_the_end_of_the_encapsulation_header() {
        // 00 01 00 00 | u8 7 | pad 3 | u32 5 | pad 0 | f64 1.5
        let mut bytes = vec![0, 1, 0, 0, 7, 0, 0, 0];
        bytes.extend(5u32.to_le_bytes());
        bytes.extend(1.5f64.to_le_bytes());
        let mut c = Cursor::new(&bytes, Wire::Cdr).expect("header");
        assert_eq!(c.u8("a").expect("a"), 7);
        assert_eq!(c.u32("b").expect("b"), 5);
        assert_eq!(c.f64("c").expect("c"), 1.5);
        assert_eq!(c.remaining(), 0);
    }

    #[test]
    fn big_endian_cdr_is_read() {
        let mut bytes = vec![0, 0, 0, 0];
        bytes.extend(0x0102_0304u32.to_be_bytes());
        let mut c = Cursor::new(&bytes, Wire::Cdr).expect("header");
        assert_eq!(c.u32("x").expect("x"), 0x0102_0304);
    }

    #[test]
    fn a_lying_sequence_length_fails_before_allocating() {
        let bytes = u32::MAX.to_le_bytes();
        let mut c = Cursor::new(&bytes, Wire::Ros1).expect("ros1");
        let err = c.sequence_len(4, "points").expect_err("too long");
        assert!(err.0.contains("points claims 4294967295"), "{err}");
    }

    #[test]
    fn strings_in_both_wire_formats() {
        let mut ros1 = 3u32.to_le_bytes().to_vec();
        ros1.extend(b"abc");
        assert_eq!(
            Cursor::new(&ros1, Wire::Ros1)
                .expect("c")
                .string("s")
                .expect("s"),
            "abc"
        );
        let mut cdr = vec![0, 1, 0, 0];
        cdr.extend(4u32.to_le_bytes());
        cdr.extend(b"abc\0");
        assert_eq!(
            Cursor::new(&cdr, Wire::Cdr)
                .expect("c")
                .string("s")
                .expect("s"),
            "abc"
        );
    }
}
