//! A minimal MATLAB v5 (.mat) writer for tests: uncompressed miMATRIX
//! elements holding real numeric arrays.

/// How a variable is stored.
pub(crate) enum MatData<'a> {
    /// A double array stored as miDOUBLE.
    Double(&'a [f64]),
    /// A double array whose integer values are stored as miUINT8, as MATLAB
    /// does to save space.
    DoubleAsU8(&'a [u8]),
}

fn tag(out: &mut Vec<u8>, data_type: u32, bytes: usize) {
    out.extend_from_slice(&data_type.to_le_bytes());
    out.extend_from_slice(&(bytes as u32).to_le_bytes());
}

fn pad8(out: &mut Vec<u8>) {
    while !out.len().is_multiple_of(8) {
        out.push(0);
    }
}

const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_DOUBLE: u32 = 9;
const MI_MATRIX: u32 = 14;
const MX_DOUBLE_CLASS: u32 = 6;

/// A whole .mat file: `(name, dimensions, data)` per variable (column-major data).
pub(crate) fn mat_v5(vars: &[(&str, &[usize], MatData<'_>)]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut text = b"MATLAB 5.0 MAT-file, written by fusepose tests".to_vec();
    text.resize(116, b' ');
    out.extend_from_slice(&text);
    out.extend_from_slice(&[0u8; 8]); // subsystem data offset
    out.extend_from_slice(&0x0100u16.to_le_bytes());
    out.extend_from_slice(b"IM");
    for (name, dims, data) in vars {
        let mut body = Vec::new();
        tag(&mut body, MI_UINT32, 8);
        body.extend_from_slice(&MX_DOUBLE_CLASS.to_le_bytes());
        body.extend_from_slice(&0u32.to_le_bytes());
        tag(&mut body, MI_INT32, 4 * dims.len());
        for &d in *dims {
            body.extend_from_slice(&(d as i32).to_le_bytes());
        }
        pad8(&mut body);
        tag(&mut body, MI_INT8, name.len());
        body.extend_from_slice(name.as_bytes());
        pad8(&mut body);
        match data {
            MatData::Double(v) => {
                tag(&mut body, MI_DOUBLE, 8 * v.len());
                for x in *v {
                    body.extend_from_slice(&x.to_le_bytes());
                }
            }
            MatData::DoubleAsU8(v) => {
                tag(&mut body, MI_UINT8, v.len());
                body.extend_from_slice(v);
            }
        }
        pad8(&mut body);
        tag(&mut out, MI_MATRIX, body.len());
        out.extend_from_slice(&body);
    }
    out
}
