//! Per-point times in cloud messages: which field holds them, in which unit, counted from
//! where, and each point's time after its frame's header stamp (the stamp convention of
//! DESIGN section 8: a frame's pose is the sensor's pose at its header stamp).
//!
//! What the common drivers write:
//!
//! | driver | field | type | unit, origin |
//! |---|---|---|---|
//! | Livox `CustomMsg` | `offset_time` | u32 | ns after the message's `timebase` |
//! | Livox driver2 PointCloud2 | `timestamp` | f64 | ns, absolute (epoch) |
//! | Ouster | `t` | u32 | ns after the scan start (the header stamp) |
//! | Velodyne | `time` | f32 | s after the header stamp |
//! | Hesai | `timestamp` | f64 | s, absolute (epoch) |
//!
//! The unit and origin are told from the values of the first frame (see
//! [`PointTimeConvention::detect`]) unless the user names the unit (`--point-time t:ns`).

use std::str::FromStr;

use super::cursor::{DecodeError, decode_err};

/// Field names read as point times when none is named, in this order.
pub const KNOWN_TIME_FIELDS: [&str; 6] = [
    "offset_time",
    "t",
    "time",
    "timestamp",
    "time_offset",
    "time_stamp",
];

/// Largest time of a point from its frame's stamp, and largest span of a frame (s).
pub const MAX_POINT_TIME_S: f64 = 1.0;

/// Shortest span a frame's times are taken to have when the unit is told from the values
/// (s): 2 ms. Unit candidates differ by 1000x, so exactly one puts a span of 2 ms to 1 s in
/// that range.
const MIN_DETECTED_SPAN_S: f64 = 2e-3;

/// Clocks this far from their epoch (s) are taken to be absolute; a simulated flight whose
/// stamps start at 0 has relative times.
const MIN_EPOCH_STAMP_S: f64 = 1000.0;

/// What to do with per-point times.
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum PointTimeChoice {
    /// The first field named as in [`KNOWN_TIME_FIELDS`], its unit told from its values.
    #[default]
    Auto,
    /// This field; its unit as given, else told from its values.
    Field {
        /// The field's name.
        name: String,
        /// Its unit, when given.
        unit: Option<TimeUnit>,
    },
    /// No times: every point at its frame's stamp.
    Ignore,
}

impl FromStr for PointTimeChoice {
    type Err = String;

    /// `auto`, `none`, `FIELD` or `FIELD:UNIT` (UNIT one of s, ms, us, ns).
    fn from_str(text: &str) -> Result<Self, String> {
        let text = text.trim();
        match text {
            "auto" => return Ok(PointTimeChoice::Auto),
            "none" => return Ok(PointTimeChoice::Ignore),
            "" => return Err("expected auto, none, FIELD or FIELD:UNIT".into()),
            _ => {}
        }
        let (name, unit) = match text.split_once(':') {
            Some((name, unit)) => (name, Some(unit.parse::<TimeUnit>()?)),
            None => (text, None),
        };
        if name.is_empty() {
            return Err(format!("'{text}': the field name is empty"));
        }
        Ok(PointTimeChoice::Field {
            name: name.to_string(),
            unit,
        })
    }
}

/// The unit of a time field's values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum TimeUnit {
    /// Seconds.
    S,
    /// Milliseconds.
    Ms,
    /// Microseconds.
    Us,
    /// Nanoseconds.
    Ns,
}

impl TimeUnit {
    /// All units, coarsest first.
    pub const ALL: [TimeUnit; 4] = [TimeUnit::S, TimeUnit::Ms, TimeUnit::Us, TimeUnit::Ns];

    /// Seconds in one unit.
    /// Nanoseconds in one of it.
    pub fn nanoseconds(self) -> i64 {
        match self {
            TimeUnit::S => 1_000_000_000,
            TimeUnit::Ms => 1_000_000,
            TimeUnit::Us => 1_000,
            TimeUnit::Ns => 1,
        }
    }

    pub fn seconds(self) -> f64 {
        match self {
            TimeUnit::S => 1.0,
            TimeUnit::Ms => 1e-3,
            TimeUnit::Us => 1e-6,
            TimeUnit::Ns => 1e-9,
        }
    }

    /// Its symbol: s, ms, us, ns.
    pub fn name(self) -> &'static str {
        match self {
            TimeUnit::S => "s",
            TimeUnit::Ms => "ms",
            TimeUnit::Us => "us",
            TimeUnit::Ns => "ns",
        }
    }
}

impl FromStr for TimeUnit {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        TimeUnit::ALL
            .into_iter()
            .find(|u| u.name() == text)
            .ok_or_else(|| format!("unit '{text}': expected s, ms, us or ns"))
    }
}

/// Where a field's times count from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum TimeOrigin {
    /// The message's header stamp.
    HeaderStamp,
    /// The clock's epoch: absolute times.
    Epoch,
    /// The Livox message's `timebase` (ns).
    Timebase,
}

/// One cloud's point times as the message stores them, one per point kept (finite
/// coordinates), in the points' order.
#[derive(Debug, Clone, PartialEq)]
pub struct RawTimes {
    /// The field they come from.
    pub field: String,
    /// Its type (`float64`, `uint32`, ...).
    pub datatype: &'static str,
    /// The values, in the field's own unit.
    pub values: Vec<f64>,
    /// The Livox `timebase` (ns); 0 for PointCloud2.
    pub base_ns: i64,
}

/// How a recording's point times read: field, unit and origin.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PointTimeConvention {
    /// The field.
    pub field: String,
    /// Its type.
    pub datatype: &'static str,
    /// Its unit.
    pub unit: TimeUnit,
    /// Where its times count from.
    pub origin: TimeOrigin,
    /// How the unit was chosen: `given`, `values` (the first frame's span) or `type` (the
    /// first frame's times did not tell: integers as ns, floats as s).
    pub unit_from: &'static str,
    /// The first frame's times: first and last point after its header stamp (s).
    pub first_frame_s: (f64, f64),
}

/// A header stamp in a time field's unit, split into whole units and the ns left over, so an
/// absolute time close to it is subtracted without the rounding of either to one `f64` (at
/// 1.7e9 s an `f64` of seconds is 0.24 us coarse, of ns 256 ns).
struct StampInUnit {
    whole: i64,
    rest_ns: i64,
    unit: TimeUnit,
}

impl StampInUnit {
    fn new(stamp_ns: i64, unit: TimeUnit) -> Self {
        let per = unit.nanoseconds();
        StampInUnit {
            whole: stamp_ns.div_euclid(per),
            rest_ns: stamp_ns.rem_euclid(per),
            unit,
        }
    }

    /// Seconds from the stamp to absolute time `v` (in the unit); NaN stays NaN.
    fn seconds_after(&self, v: f64) -> f64 {
        // An integer-valued `v` (any ns clock beyond 2^53) is subtracted as an integer; else
        // `v` is below 2^53 in magnitude, the whole part is exact as an `f64` and the two are
        // close: the difference is exact (Sterbenz).
        let units = if v.fract() == 0.0 && v.abs() < 9.0e18 {
            (v as i128 - i128::from(self.whole)) as f64
        } else {
            v - self.whole as f64
        };
        units * self.unit.seconds() - self.rest_ns as f64 * 1e-9
    }
}

fn min_max(values: &[f64]) -> Option<(f64, f64)> {
    let finite = values.iter().copied().filter(|v| v.is_finite());
    finite.fold(None, |acc, v| {
        Some(acc.map_or((v, v), |(lo, hi): (f64, f64)| (lo.min(v), hi.max(v))))
    })
}

fn median(values: &[f64]) -> f64 {
    let mut sorted: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f64::total_cmp);
    sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN)
}

impl PointTimeConvention {
    /// Tells the unit and origin from one frame's times at header stamp `stamp_ns` (unless
    /// `unit` is given):
    /// - Livox `offset_time` counts ns from the message's timebase;
    /// - absolute: some unit puts the times' median within [`MAX_POINT_TIME_S`] of a stamp
    ///   that is itself far from the epoch (a real clock);
    /// - else relative to the stamp, in the unit that makes the span 2 ms to 1 s; when no
    ///   unit does (every point at one time), integers are read as ns and floats as s.
    pub fn detect(
        raw: &RawTimes,
        stamp_ns: i64,
        unit: Option<TimeUnit>,
    ) -> Result<Self, DecodeError> {
        let stamp_s = crate::recording::stamp_s(stamp_ns);
        let integer = raw.datatype.contains("int");
        let (unit, origin, unit_from) = if raw.base_ns != 0 || raw.field == "offset_time" {
            let origin = if raw.base_ns != 0 {
                TimeOrigin::Timebase
            } else {
                TimeOrigin::HeaderStamp
            };
            (unit.unwrap_or(TimeUnit::Ns), origin, "type")
        } else {
            let m = median(&raw.values);
            let absolute = |u: TimeUnit| {
                stamp_s.abs() >= MIN_EPOCH_STAMP_S && (m * u.seconds() - stamp_s).abs() <= 1.0
            };
            match unit {
                Some(u) if absolute(u) => (u, TimeOrigin::Epoch, "given"),
                Some(u) => (u, TimeOrigin::HeaderStamp, "given"),
                None => match TimeUnit::ALL.into_iter().find(|&u| absolute(u)) {
                    Some(u) => (u, TimeOrigin::Epoch, "values"),
                    None => {
                        let span = min_max(&raw.values).map_or(0.0, |(lo, hi)| hi - lo);
                        let fits = |u: TimeUnit| {
                            (MIN_DETECTED_SPAN_S..=MAX_POINT_TIME_S).contains(&(span * u.seconds()))
                        };
                        match TimeUnit::ALL.into_iter().find(|&u| fits(u)) {
                            Some(u) => (u, TimeOrigin::HeaderStamp, "values"),
                            None if span == 0.0 || span.is_nan() => {
                                let u = if integer { TimeUnit::Ns } else { TimeUnit::S };
                                (u, TimeOrigin::HeaderStamp, "type")
                            }
                            None => {
                                return Err(decode_err(format!(
                                    "field {} ({}): its times span {span} (in its own unit) \
                                     and no unit makes that 2 ms to 1 s; name the unit with \
                                     --point-time {}:UNIT, or --point-time none",
                                    raw.field, raw.datatype, raw.field
                                )));
                            }
                        }
                    }
                },
            }
        };
        let mut convention = PointTimeConvention {
            field: raw.field.clone(),
            datatype: raw.datatype,
            unit,
            origin,
            unit_from,
            first_frame_s: (0.0, 0.0),
        };
        let offsets = convention.offsets_s(raw, stamp_ns)?;
        convention.first_frame_s = offsets
            .iter()
            .map(|&t| f64::from(t))
            .fold(None, |acc, t| {
                Some(acc.map_or((t, t), |(lo, hi): (f64, f64)| (lo.min(t), hi.max(t))))
            })
            .unwrap_or((0.0, 0.0));
        Ok(convention)
    }

    /// Each point's time after header stamp `stamp_ns` (s), checked: finite, within
    /// [`MAX_POINT_TIME_S`] of the stamp, spanning at most that. Out-of-order times are fine.
    pub fn offsets_s(&self, raw: &RawTimes, stamp_ns: i64) -> Result<Vec<f32>, DecodeError> {
        let unit_s = self.unit.seconds();
        let field = &raw.field;
        if *field != self.field {
            return Err(decode_err(format!(
                "point times are in field {field}, the first frame's were in {}",
                self.field
            )));
        }
        // Offsets of the base from the stamp in integer ns first: absolute clocks keep their
        // precision.
        let base_s = match self.origin {
            TimeOrigin::HeaderStamp | TimeOrigin::Epoch => 0.0,
            TimeOrigin::Timebase => (raw.base_ns - stamp_ns) as f64 * 1e-9,
        };
        let stamp_in_unit = StampInUnit::new(stamp_ns, self.unit);
        let mut offsets = Vec::with_capacity(raw.values.len());
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (i, &v) in raw.values.iter().enumerate() {
            let t = match self.origin {
                TimeOrigin::Epoch => stamp_in_unit.seconds_after(v),
                _ => base_s + v * unit_s,
            };
            if !t.is_finite() {
                return Err(decode_err(format!(
                    "field {field}: point {i}'s time is {v}, not a finite number"
                )));
            }
            if t.abs() > MAX_POINT_TIME_S {
                return Err(decode_err(format!(
                    "field {field}: point {i} is {t:.6} s from the header stamp ({v} {} {}), \
                     more than {MAX_POINT_TIME_S} s; if the unit is wrong name it with \
                     --point-time {field}:UNIT, or ignore the times with --point-time none",
                    self.unit.name(),
                    match self.origin {
                        TimeOrigin::HeaderStamp => "after the stamp",
                        TimeOrigin::Epoch => "absolute",
                        TimeOrigin::Timebase => "after the timebase",
                    }
                )));
            }
            lo = lo.min(t);
            hi = hi.max(t);
            offsets.push(t as f32);
        }
        if hi - lo > MAX_POINT_TIME_S {
            return Err(decode_err(format!(
                "field {field}: the frame's times span {:.6} s, more than {MAX_POINT_TIME_S} s",
                hi - lo
            )));
        }
        Ok(offsets)
    }

    /// One line for `pssba inspect`.
    pub fn describe(&self) -> String {
        let origin = match self.origin {
            TimeOrigin::HeaderStamp => "after the header stamp",
            TimeOrigin::Epoch => "absolute",
            TimeOrigin::Timebase => "after the message's timebase",
        };
        let (a, b) = self.first_frame_s;
        format!(
            "field {} ({}), {} {origin} (unit from {}); first frame {:.1} to {:.1} ms after its \
             stamp (span {:.1} ms)",
            self.field,
            self.datatype,
            self.unit.name(),
            self.unit_from,
            a * 1e3,
            b * 1e3,
            (b - a) * 1e3
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(field: &str, datatype: &'static str, values: Vec<f64>) -> RawTimes {
        RawTimes {
            field: field.into(),
            datatype,
            values,
            base_ns: 0,
        }
    }

    const STAMP_NS: i64 = 1_700_000_000_000_000_000;

    #[test]
    fn choices_parse() {
        assert_eq!("none".parse(), Ok(PointTimeChoice::Ignore));
        assert_eq!("auto".parse(), Ok(PointTimeChoice::Auto));
        assert_eq!(
            "t:ns".parse(),
            Ok(PointTimeChoice::Field {
                name: "t".into(),
                unit: Some(TimeUnit::Ns)
            })
        );
        assert_eq!(
            "time".parse(),
            Ok(PointTimeChoice::Field {
                name: "time".into(),
                unit: None
            })
        );
        for bad in ["", "t:hours", ":ns"] {
            assert!(bad.parse::<PointTimeChoice>().is_err(), "{bad}");
        }
    }

    #[test]
    fn each_driver_convention_is_told_from_its_values() {
        let frame = |scale: f64, base: f64| -> Vec<f64> {
            (0..=100).map(|i| base + i as f64 * 1e-3 / scale).collect()
        };
        let stamp_s = 1.7e9;
        // (field, type, values, unit, origin)
        let cases = [
            (
                "t",
                "uint32",
                frame(1e-9, 0.0),
                TimeUnit::Ns,
                TimeOrigin::HeaderStamp,
            ),
            (
                "time",
                "float32",
                frame(1.0, 0.0),
                TimeUnit::S,
                TimeOrigin::HeaderStamp,
            ),
            (
                "timestamp",
                "float64",
                frame(1.0, stamp_s),
                TimeUnit::S,
                TimeOrigin::Epoch,
            ),
            (
                "timestamp",
                "float64",
                frame(1e-9, stamp_s * 1e9),
                TimeUnit::Ns,
                TimeOrigin::Epoch,
            ),
            (
                "time",
                "float32",
                frame(1e-6, 0.0),
                TimeUnit::Us,
                TimeOrigin::HeaderStamp,
            ),
        ];
        for (field, datatype, values, unit, origin) in cases {
            let raw = raw(field, datatype, values);
            let c = PointTimeConvention::detect(&raw, STAMP_NS, None).expect(field);
            assert_eq!((c.unit, c.origin), (unit, origin), "{field} {datatype}");
            let t = c.offsets_s(&raw, STAMP_NS).expect("offsets");
            assert!(t[0].abs() < 1e-6, "{field}: {}", t[0]);
            assert!((t[100] - 0.1).abs() < 1e-6, "{field}: {}", t[100]);
        }
    }

    #[test]
    fn livox_offsets_count_from_the_timebase() {
        let raw = RawTimes {
            field: "offset_time".into(),
            datatype: "uint32",
            values: vec![0.0, 5e7, 1e8],
            base_ns: STAMP_NS - 10_000_000,
        };
        let c = PointTimeConvention::detect(&raw, STAMP_NS, None).expect("livox");
        assert_eq!(c.origin, TimeOrigin::Timebase);
        let t = c.offsets_s(&raw, STAMP_NS).expect("offsets");
        assert!(
            (t[0] + 0.01).abs() < 1e-7 && (t[2] - 0.09).abs() < 1e-7,
            "{t:?}"
        );
    }

    #[test]
    fn bad_times_are_refused_naming_the_field() {
        let c = PointTimeConvention::detect(&raw("time", "float32", vec![0.0, 0.05]), 0, None)
            .expect("time");
        let nan = c.offsets_s(&raw("time", "float32", vec![0.0, f64::NAN]), 0);
        assert!(nan.expect_err("NaN").0.contains("point 1"));
        let far = c.offsets_s(&raw("time", "float32", vec![0.0, 3.0]), 0);
        assert!(far.expect_err("3 s").0.contains("--point-time time:UNIT"));
        let span = c.offsets_s(&raw("time", "float32", vec![-0.6, 0.6]), 0);
        assert!(span.expect_err("span").0.contains("span"));
        let other = c.offsets_s(&raw("t", "uint32", vec![0.0]), 0);
        assert!(other.is_err());
        // Out of order and before the stamp within the span: fine.
        let fine = c.offsets_s(&raw("time", "float32", vec![0.05, -0.02, 0.01]), 0);
        assert_eq!(fine.expect("fine").len(), 3);
        // A span of 1.5 in its own unit: 1.5 s, 1.5 ms, ...: no unit makes it 2 ms to 1 s.
        let none = PointTimeConvention::detect(&raw("time", "float64", vec![0.0, 1.5]), 0, None);
        assert!(none.is_err());
    }

    #[test]
    fn absolute_clocks_are_subtracted_without_rounding_the_stamp() {
        // A stamp that no f64 of s or ns holds exactly: 1.7e9 s + 123456789 ns.
        let stamp_ns = STAMP_NS + 123_456_789;
        let offsets_ns = [0_i64, 1, 49_999_999, 99_800_000];
        // ns as f64, as the Livox driver casts base_time + offset_time: the value's own
        // rounding (256 ns at this magnitude) is all that is left.
        let ns: Vec<f64> = offsets_ns.iter().map(|o| (stamp_ns + o) as f64).collect();
        let c =
            PointTimeConvention::detect(&raw("timestamp", "float64", ns.clone()), stamp_ns, None)
                .expect("ns");
        assert_eq!((c.unit, c.origin), (TimeUnit::Ns, TimeOrigin::Epoch));
        let t = c
            .offsets_s(&raw("timestamp", "float64", ns.clone()), stamp_ns)
            .expect("ns");
        for ((o, v), t) in offsets_ns.iter().zip(&ns).zip(&t) {
            let exact = (*v as i128 - i128::from(stamp_ns)) as f64 * 1e-9;
            assert!((f64::from(*t) - exact).abs() < 1e-8, "{o}: {t} vs {exact}");
            assert!(
                (f64::from(*t) - *o as f64 * 1e-9).abs() < 1.3e-7,
                "{o}: {t}"
            );
        }
        // s as f64 (Hesai): within half the value's own 0.24 us step.
        let s: Vec<f64> = offsets_ns
            .iter()
            .map(|o| 1.7e9 + (123_456_789 + o) as f64 * 1e-9)
            .collect();
        let c =
            PointTimeConvention::detect(&raw("timestamp", "float64", s.clone()), stamp_ns, None)
                .expect("s");
        assert_eq!((c.unit, c.origin), (TimeUnit::S, TimeOrigin::Epoch));
        let t = c
            .offsets_s(&raw("timestamp", "float64", s), stamp_ns)
            .expect("s");
        for (o, t) in offsets_ns.iter().zip(&t) {
            assert!(
                (f64::from(*t) - *o as f64 * 1e-9).abs() < 1.3e-7,
                "{o}: {t}"
            );
        }
    }

    #[test]
    fn times_all_at_one_instant_take_the_type_default() {
        let c = PointTimeConvention::detect(&raw("t", "uint32", vec![0.0; 4]), STAMP_NS, None)
            .expect("t");
        assert_eq!((c.unit, c.unit_from), (TimeUnit::Ns, "type"));
        let c = PointTimeConvention::detect(&raw("time", "float32", vec![0.0; 4]), 0, None)
            .expect("time");
        assert_eq!(c.unit, TimeUnit::S);
    }
}
