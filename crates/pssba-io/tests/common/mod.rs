//! Hand-built PCD files for the integration tests.

#![allow(dead_code)]

use pssba_io::{PcdEncoding, lzf};

/// One header field: name, SIZE, TYPE, COUNT.
#[derive(Debug, Clone, Copy)]
pub struct F(pub &'static str, pub usize, pub char, pub usize);

/// Little-endian bytes of `v` stored as TYPE `ty` with SIZE `size`.
pub fn encode(ty: char, size: usize, v: f64) -> Vec<u8> {
    match (ty, size) {
        ('F', 4) => (v as f32).to_le_bytes().to_vec(),
        ('F', 8) => v.to_le_bytes().to_vec(),
        ('I', _) => (v as i64).to_le_bytes()[..size].to_vec(),
        ('U', _) => (v as u64).to_le_bytes()[..size].to_vec(),
        _ => panic!("bad type {ty}{size}"),
    }
}

/// Text of `v` as TYPE `ty` with SIZE `size`.
pub fn text(ty: char, size: usize, v: f64) -> String {
    match (ty, size) {
        ('F', 4) => format!("{}", v as f32),
        ('F', _) => format!("{v}"),
        _ => format!("{}", v as i64),
    }
}

/// Header lines for `fields` and `n` points (WIDTH n, HEIGHT 1).
pub fn header(fields: &[F], n: usize, data: &str) -> String {
    let col = |f: &dyn Fn(&F) -> String| fields.iter().map(f).collect::<Vec<_>>().join(" ");
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {}\nSIZE {}\nTYPE {}\nCOUNT {}\n\
         WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n",
        col(&|f| f.0.to_string()),
        col(&|f| f.1.to_string()),
        col(&|f| f.2.to_string()),
        col(&|f| f.3.to_string()),
    )
}

/// Builds a whole PCD file. `values[i][f][c]` is point i, field f, element c.
pub fn build(fields: &[F], values: &[Vec<Vec<f64>>], enc: PcdEncoding) -> Vec<u8> {
    let mut out = header(fields, values.len(), enc.as_str()).into_bytes();
    match enc {
        PcdEncoding::Ascii => {
            for point in values {
                let mut words = Vec::new();
                for (f, vals) in fields.iter().zip(point) {
                    words.extend(vals.iter().map(|&v| text(f.2, f.1, v)));
                }
                out.extend_from_slice(words.join(" ").as_bytes());
                out.push(b'\n');
            }
        }
        PcdEncoding::Binary => {
            for point in values {
                for (f, vals) in fields.iter().zip(point) {
                    vals.iter().for_each(|&v| out.extend(encode(f.2, f.1, v)));
                }
            }
        }
        PcdEncoding::BinaryCompressed => {
            let mut raw = Vec::new();
            for (k, f) in fields.iter().enumerate() {
                for point in values {
                    point[k]
                        .iter()
                        .for_each(|&v| raw.extend(encode(f.2, f.1, v)));
                }
            }
            let packed = lzf::compress(&raw);
            out.extend((packed.len() as u32).to_le_bytes());
            out.extend((raw.len() as u32).to_le_bytes());
            out.extend(packed);
        }
    }
    out
}

/// Deterministic values for every field of `n` points; x, y, z (wherever
/// they are) hold the returned coordinates.
pub fn sample(fields: &[F], n: usize) -> (Vec<Vec<Vec<f64>>>, Vec<[f64; 3]>) {
    let mut values = Vec::new();
    let mut xyz = Vec::new();
    for i in 0..n {
        let p = [
            i as f64 * 0.5 - 3.25,
            100.0 + i as f64 * 0.125,
            -(i as f64) * 2.0,
        ];
        let point = fields
            .iter()
            .map(|f| {
                (0..f.3)
                    .map(|c| match f.0 {
                        "x" => p[0],
                        "y" => p[1],
                        "z" => p[2],
                        _ => ((i * 7 + c * 3) % 100) as f64 + if f.2 == 'F' { 0.5 } else { 0.0 },
                    })
                    .collect()
            })
            .collect();
        values.push(point);
        xyz.push(p);
    }
    (values, xyz)
}

pub const ENCODINGS: [PcdEncoding; 3] = [
    PcdEncoding::Ascii,
    PcdEncoding::Binary,
    PcdEncoding::BinaryCompressed,
];
