//! PCD round trips and files with extra fields.

#![allow(clippy::unwrap_used)]

mod common;

use common::{ENCODINGS, F, build, sample};
use nalgebra::Point3;
use pssba_io::{
    PcdEncoding, PcdPrecision, pcd_to_bytes, read_pcd, read_pcd_from_bytes, write_pcd,
    write_pcd_with_precision,
};

fn cloud() -> Vec<Point3<f64>> {
    let mut pts: Vec<Point3<f64>> = (0..500)
        .map(|k| {
            let t = k as f64 * 0.37;
            Point3::new(
                50.0 * t.cos(),
                50.0 * t.sin(),
                0.01 * k as f64 - 1.234_567_891,
            )
        })
        .collect();
    pts.push(Point3::new(f64::NAN, f64::NAN, f64::NAN));
    pts.push(Point3::new(f64::INFINITY, -f64::INFINITY, 0.0));
    pts.push(Point3::new(1e-30, -123_456.789_012_345, 3.0));
    pts
}

/// Equal as the stored precision sees them (NaN equals NaN).
fn same(a: f64, b: f64, precision: PcdPrecision) -> bool {
    let a = match precision {
        PcdPrecision::F32 => f64::from(a as f32),
        PcdPrecision::F64 => a,
    };
    a == b || (a.is_nan() && b.is_nan())
}

#[test]
fn round_trip_all_encodings_and_precisions() {
    let dir = tempfile::tempdir().unwrap();
    let pts = cloud();
    for enc in ENCODINGS {
        for prec in [PcdPrecision::F32, PcdPrecision::F64] {
            let path = dir.path().join(format!("{enc}_{prec:?}.pcd"));
            write_pcd_with_precision(&path, &pts, enc, prec).unwrap();
            let back = read_pcd(&path).unwrap();
            assert_eq!(back.len(), pts.len(), "{enc} {prec:?}");
            for (p, q) in pts.iter().zip(&back) {
                for k in 0..3 {
                    assert!(same(p[k], q[k], prec), "{enc} {prec:?}: {p} vs {q}");
                }
            }
        }
    }
}

#[test]
fn default_writer_is_f32_and_empty_clouds_work() {
    let pts = [Point3::new(0.1, 0.2, 0.3)];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.pcd");
    write_pcd(&path, &pts, PcdEncoding::Binary).unwrap();
    let text = std::fs::read(&path).unwrap();
    assert!(String::from_utf8_lossy(&text).contains("SIZE 4 4 4\nTYPE F F F\n"));
    assert_eq!(read_pcd(&path).unwrap()[0].x, f64::from(0.1f32));
    for enc in ENCODINGS {
        let bytes = pcd_to_bytes(&[], enc, PcdPrecision::F32, "e.pcd").unwrap();
        assert!(
            read_pcd_from_bytes(&bytes, "e.pcd").unwrap().is_empty(),
            "{enc}"
        );
    }
}

fn check_layout(fields: &[F], n: usize) {
    let (values, xyz) = sample(fields, n);
    for enc in ENCODINGS {
        let bytes = build(fields, &values, enc);
        let pts = read_pcd_from_bytes(&bytes, "frame.pcd")
            .unwrap_or_else(|e| panic!("{enc} {fields:?}: {e}"));
        assert_eq!(pts.len(), n);
        for (p, q) in pts.iter().zip(&xyz) {
            assert_eq!([p.x, p.y, p.z], *q, "{enc} {fields:?}");
        }
    }
}

#[test]
fn skips_lidar_fields() {
    let fields = [
        F("x", 4, 'F', 1),
        F("y", 4, 'F', 1),
        F("z", 4, 'F', 1),
        F("intensity", 4, 'F', 1),
        F("t", 4, 'U', 1),
        F("ring", 2, 'U', 1),
    ];
    check_layout(&fields, 37);
}

#[test]
fn skips_rgb_and_multi_count_fields() {
    let fields = [
        F("rgb", 4, 'U', 1),
        F("x", 4, 'F', 1),
        F("normal", 4, 'F', 3),
        F("y", 4, 'F', 1),
        F("_", 1, 'U', 3),
        F("z", 4, 'F', 1),
        F("label", 1, 'I', 1),
        F("stamp", 8, 'F', 1),
    ];
    check_layout(&fields, 41);
}

#[test]
fn reads_f8_coordinates() {
    let fields = [
        F("t", 8, 'F', 1),
        F("x", 8, 'F', 1),
        F("y", 8, 'F', 1),
        F("z", 8, 'F', 1),
    ];
    check_layout(&fields, 20);
    let mixed = [
        F("x", 8, 'F', 1),
        F("y", 4, 'F', 1),
        F("z", 8, 'F', 1),
        F("i", 8, 'I', 2),
    ];
    check_layout(&mixed, 20);
}

#[test]
fn organised_cloud_crlf_comments_and_nan_text() {
    let text = "# comment\r\nVERSION .7\r\nFIELDS x y z\r\nSIZE 4 4 4\r\nTYPE F F F\r\n\
        WIDTH 2\r\n# another\r\nHEIGHT 2\r\nVIEWPOINT 0 0 0 1 0 0 0\r\nPOINTS 4\r\nDATA ascii\r\n\
        1 2 3\r\nnan nan nan\r\n\r\n-1.5 0 1e3\r\n  4 5 6  \r\n";
    let pts = read_pcd_from_bytes(text.as_bytes(), "org.pcd").unwrap();
    assert_eq!(pts.len(), 4);
    assert_eq!(pts[0], Point3::new(1.0, 2.0, 3.0));
    assert!(pts[1].x.is_nan() && pts[1].z.is_nan());
    assert_eq!(pts[2], Point3::new(-1.5, 0.0, 1000.0));
    assert_eq!(pts[3], Point3::new(4.0, 5.0, 6.0));
}

#[test]
fn point_times_round_trip_in_every_encoding() {
    let points = cloud();
    let times: Vec<f32> = (0..points.len())
        .map(|k| k as f32 * 1.7e-4 - 0.01)
        .collect();
    for enc in ENCODINGS {
        for precision in [PcdPrecision::F32, PcdPrecision::F64] {
            let bytes =
                pssba_io::pcd_to_bytes_with_times(&points, Some(&times), enc, precision, "mem.pcd")
                    .unwrap();
            let (read, read_times) =
                pssba_io::read_pcd_with_times_from_bytes(&bytes, "mem.pcd").unwrap();
            assert_eq!(
                read_times.as_deref(),
                Some(&times[..]),
                "{enc} {precision:?}"
            );
            assert_eq!(read.len(), points.len());
            for (a, b) in points.iter().zip(&read) {
                for axis in 0..3 {
                    assert!(same(a[axis], b[axis], precision), "{enc} {a} {b}");
                }
            }
            // Readers that know nothing of times read the same points.
            let plain = read_pcd_from_bytes(&bytes, "mem.pcd").unwrap();
            assert_eq!(plain.len(), read.len());
        }
        // Without a time field: no times.
        let bytes = pcd_to_bytes(&points, enc, PcdPrecision::F32, "mem.pcd").unwrap();
        let (_, none) = pssba_io::read_pcd_with_times_from_bytes(&bytes, "mem.pcd").unwrap();
        assert!(none.is_none());
    }
}

#[test]
fn a_time_field_of_another_type_is_refused_naming_it() {
    let bytes = pcd_to_bytes(&cloud(), PcdEncoding::Ascii, PcdPrecision::F32, "m.pcd").unwrap();
    let text = String::from_utf8(bytes).unwrap();
    // Rename z's neighbour: a file whose fourth field `time` is an unsigned integer.
    let text = text
        .replace("FIELDS x y z", "FIELDS x y z time")
        .replace("SIZE 4 4 4", "SIZE 4 4 4 4")
        .replace("TYPE F F F", "TYPE F F F U")
        .replace("COUNT 1 1 1", "COUNT 1 1 1 1")
        .lines()
        .map(|l| {
            if l.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == 'n' || c == 'i') {
                format!("{l} 7")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let err = pssba_io::read_pcd_with_times_from_bytes(text.as_bytes(), "m.pcd").unwrap_err();
    let message = err.to_string();
    assert!(
        message.contains("m.pcd") && message.contains("time"),
        "{message}"
    );
    // The plain reader still reads its points.
    assert_eq!(
        read_pcd_from_bytes(text.as_bytes(), "m.pcd").unwrap().len(),
        cloud().len()
    );
}
