//! The sRGB transfer function (IEC 61966-2-1) in double precision, for code
//! that edits 8-bit colour in linear light outside the renderer (colour
//! casts in `fusepose eval`, camera casts in segmenter training).

/// sRGB code value → linear light in 0..=1.
pub fn decode(v: u8) -> f64 {
    let c = v as f64 / 255.0;
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// Linear light → sRGB code value (clipped, rounded).
pub fn encode(l: f64) -> u8 {
    let l = l.clamp(0.0, 1.0);
    let c = if l <= 0.003_130_8 { 12.92 * l } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 };
    (c * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    #[test]
    fn decode_then_encode_is_the_identity_on_every_code() {
        for v in 0..=255u8 {
            assert_eq!(super::encode(super::decode(v)), v);
        }
        assert_eq!((super::decode(0), super::decode(255)), (0.0, 1.0));
    }
}
