//! Minimal NumPy `.npy` (format 1.0) writer and reader for little-endian `f64` arrays.
//!
//! Layout (numpy.lib.format): the magic `\x93NUMPY`, version bytes `1 0`, a little-endian
//! `u16` header length, an ASCII Python-dict header
//! `{'descr': '<f8', 'fortran_order': False, 'shape': (..), }` padded with spaces and a final
//! newline so that the data starts at a multiple of 64 bytes, then the values in C order.

use crate::error::{ModalError, Result};
use std::path::Path;

/// An n-dimensional `f64` array in C (row-major) order.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// Shape (empty for a scalar).
    pub shape: Vec<usize>,
    /// Values in C order; `len = Π shape`.
    pub data: Vec<f64>,
}

fn io(path: &Path, e: std::io::Error) -> ModalError {
    ModalError::Io { path: path.display().to_string(), source: e }
}

fn format_err(path: &Path, reason: impl Into<String>) -> ModalError {
    ModalError::Format { path: path.display().to_string(), reason: reason.into() }
}

/// Encodes an array as `.npy` bytes.
pub fn to_bytes(a: &NpyArray) -> Vec<u8> {
    let shape = match a.shape.len() {
        0 => "()".to_string(),
        1 => format!("({},)", a.shape[0]),
        _ => format!("({})", a.shape.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ")),
    };
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}");
    let unpadded = 10 + header.len() + 1;
    let pad = (64 - unpadded % 64) % 64;
    header.push_str(&" ".repeat(pad));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + 8 * a.data.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in &a.data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Writes an array to `path`.
pub fn write(path: &Path, a: &NpyArray) -> Result<()> {
    let expected: usize = a.shape.iter().product();
    if expected != a.data.len() {
        return Err(format_err(
            path,
            format!("shape {:?} needs {expected} values, got {}", a.shape, a.data.len()),
        ));
    }
    std::fs::write(path, to_bytes(a)).map_err(|e| io(path, e))
}

/// Decodes `.npy` bytes (`<f8`, C or Fortran order; Fortran data is returned in C order).
pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<NpyArray> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(format_err(path, "missing the \\x93NUMPY magic"));
    }
    let (major, start, hlen) = match bytes[6] {
        1 => (1, 10, u16::from_le_bytes([bytes[8], bytes[9]]) as usize),
        2 | 3 if bytes.len() >= 12 => {
            (bytes[6], 12, u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize)
        }
        v => return Err(format_err(path, format!("unsupported .npy version {v}"))),
    };
    let _ = major;
    let header = bytes
        .get(start..start + hlen)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or_else(|| format_err(path, "truncated or non-UTF-8 header"))?;
    let field = |key: &str| -> Option<&str> {
        let i = header.find(&format!("'{key}'"))?;
        let rest = &header[i + key.len() + 2..];
        let rest = rest.trim_start().strip_prefix(':')?.trim_start();
        Some(rest)
    };
    let descr = field("descr").ok_or_else(|| format_err(path, "header has no 'descr'"))?;
    if !(descr.starts_with("'<f8'") || descr.starts_with("'float64'")) {
        return Err(format_err(
            path,
            format!(
                "only little-endian f64 ('<f8') is supported, got {}",
                &descr[..descr.len().min(8)]
            ),
        ));
    }
    let fortran = field("fortran_order")
        .ok_or_else(|| format_err(path, "header has no 'fortran_order'"))?
        .starts_with("True");
    let shape_text = field("shape").ok_or_else(|| format_err(path, "header has no 'shape'"))?;
    let close = shape_text.find(')').ok_or_else(|| format_err(path, "malformed shape"))?;
    let inner = shape_text.get(1..close).ok_or_else(|| format_err(path, "malformed shape"))?;
    let mut shape = Vec::new();
    for part in inner.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        shape.push(
            part.parse::<usize>()
                .map_err(|_| format_err(path, format!("bad shape entry `{part}`")))?,
        );
    }
    let n: usize = shape.iter().product();
    let body = &bytes[start + hlen..];
    if body.len() != 8 * n {
        return Err(format_err(
            path,
            format!("shape {shape:?} needs {} data bytes, found {}", 8 * n, body.len()),
        ));
    }
    let raw: Vec<f64> =
        body.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes"))).collect();
    let data = if fortran && shape.len() > 1 {
        // convert column-major to row-major
        let mut out = vec![0.0; n];
        let nd = shape.len();
        let mut idx = vec![0usize; nd];
        for (f, v) in raw.iter().enumerate() {
            let mut rem = f;
            for d in 0..nd {
                idx[d] = rem % shape[d];
                rem /= shape[d];
            }
            let mut c = 0;
            for d in 0..nd {
                c = c * shape[d] + idx[d];
            }
            out[c] = *v;
        }
        out
    } else {
        raw
    };
    Ok(NpyArray { shape, data })
}

/// Reads an array from `path`.
pub fn read(path: &Path) -> Result<NpyArray> {
    let bytes = std::fs::read(path).map_err(|e| io(path, e))?;
    from_bytes(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_aligned_and_round_trips() {
        let a = NpyArray {
            shape: vec![2, 3],
            data: vec![1.0, -2.5, 3.0, f64::MIN_POSITIVE, 0.0, 1e300],
        };
        let bytes = to_bytes(&a);
        let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + hlen) % 64, 0);
        assert_eq!(bytes[10 + hlen - 1], b'\n');
        let b = from_bytes(Path::new("mem"), &bytes).unwrap();
        assert_eq!(a, b);
        let v = NpyArray { shape: vec![4], data: vec![1.0, 2.0, 3.0, 4.0] };
        let text = String::from_utf8_lossy(&to_bytes(&v)).to_string();
        assert!(text.contains("'shape': (4,), }"));
    }

    #[test]
    fn fortran_order_is_transposed_to_c_order() {
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        let mut header = "{'descr': '<f8', 'fortran_order': True, 'shape': (2, 3), }".to_string();
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        for v in [1.0f64, 4.0, 2.0, 5.0, 3.0, 6.0] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let a = from_bytes(Path::new("mem"), &bytes).unwrap();
        assert_eq!(a.data, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }

    #[test]
    fn malformed_files_are_errors() {
        assert!(from_bytes(Path::new("x"), b"hello").is_err());
        let mut bytes = to_bytes(&NpyArray { shape: vec![3], data: vec![1.0; 3] });
        bytes.pop();
        assert!(from_bytes(Path::new("x"), &bytes).is_err());
    }
}
