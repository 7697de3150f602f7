//! The size an image file declares, read from its header before any decoding, so a
//! file that lies about its size (a 60000×60000 PNG in a 640×480 recording) is refused
//! before the decoder allocates for it. PNG: the IHDR chunk; JPEG: the first
//! start-of-frame marker.

/// The eight bytes every PNG file starts with.
pub(super) const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];

/// Width and height declared by a PNG or JPEG header, or why they cannot be read.
pub fn declared_size(bytes: &[u8]) -> Result<(u32, u32), String> {
    if bytes.starts_with(&PNG_SIGNATURE) {
        return png_size(bytes);
    }
    if bytes.starts_with(&[0xff, 0xd8]) {
        return jpeg_size(bytes);
    }
    Err("neither PNG nor JPEG".into())
}

fn be_u16(bytes: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_be_bytes(bytes.get(at..at + 2)?.try_into().ok()?))
}

fn be_u32(bytes: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_be_bytes(bytes.get(at..at + 4)?.try_into().ok()?))
}

/// The IHDR chunk must come first (PNG spec 11.2.2): length 13, then width and height.
fn png_size(bytes: &[u8]) -> Result<(u32, u32), String> {
    if bytes.get(12..16) != Some(b"IHDR") || be_u32(bytes, 8) != Some(13) {
        return Err("PNG without an IHDR chunk first".into());
    }
    match (be_u32(bytes, 16), be_u32(bytes, 20)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err("PNG header cut short".into()),
    }
}

/// Walks the marker segments from SOI to the first SOFn (baseline, progressive,
/// lossless or arithmetic); the image data (SOS) must not come first.
fn jpeg_size(bytes: &[u8]) -> Result<(u32, u32), String> {
    let mut at = 2;
    loop {
        // Markers may be preceded by any number of 0xFF fill bytes (ITU T.81 B.1.1.2).
        while bytes.get(at) == Some(&0xff) && bytes.get(at + 1) == Some(&0xff) {
            at += 1;
        }
        let (Some(&0xff), Some(&marker)) = (bytes.get(at), bytes.get(at + 1)) else {
            return Err("JPEG without a frame header (SOF) before its data".into());
        };
        at += 2;
        match marker {
            // Standalone markers: no length field.
            0x01 | 0xd0..=0xd7 => continue,
            0xda | 0xd9 => return Err("JPEG data before its frame header (SOF)".into()),
            // Not a marker (a stuffed 0x00, or a reserved code): libjpeg would skip
            // these and scan on, possibly to another SOF than the one found here.
            0x00 | 0x02..=0xbf => {
                return Err(format!(
                    "JPEG byte 0xff 0x{marker:02x} where a marker should be"
                ))
            }
            _ => {}
        }
        let Some(length) = be_u16(bytes, at) else {
            return Err("JPEG header cut short".into());
        };
        let is_sof = matches!(marker, 0xc0..=0xc3 | 0xc5..=0xc7 | 0xc9..=0xcb | 0xcd..=0xcf);
        if is_sof {
            // length(2) precision(1) height(2) width(2)
            return match (be_u16(bytes, at + 3), be_u16(bytes, at + 5)) {
                (Some(h), Some(w)) => Ok((w as u32, h as u32)),
                _ => Err("JPEG frame header cut short".into()),
            };
        }
        if length < 2 {
            return Err(format!("JPEG marker 0x{marker:02x} with length {length}"));
        }
        at += length as usize;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opencv::core as cv;
    use opencv::prelude::*;

    fn encode(ext: &str, width: i32, height: i32) -> Vec<u8> {
        let m =
            cv::Mat::new_rows_cols_with_default(height, width, cv::CV_8UC3, cv::Scalar::all(9.0))
                .unwrap();
        let mut out = cv::Vector::<u8>::new();
        opencv::imgcodecs::imencode_def(ext, &m, &mut out).unwrap();
        out.to_vec()
    }

    #[test]
    fn reads_the_size_of_png_and_jpeg() {
        assert_eq!(declared_size(&encode(".png", 17, 5)), Ok((17, 5)));
        assert_eq!(declared_size(&encode(".jpg", 33, 21)), Ok((33, 21)));
    }

    #[test]
    fn a_huge_declared_size_is_read_without_decoding() {
        let mut png = encode(".png", 8, 4);
        png[16..20].copy_from_slice(&60000u32.to_be_bytes());
        png[20..24].copy_from_slice(&60000u32.to_be_bytes());
        assert_eq!(declared_size(&png), Ok((60000, 60000)));
    }

    #[test]
    fn cut_or_foreign_headers_are_errors_not_panics() {
        let jpeg = encode(".jpg", 8, 8);
        for n in 0..40 {
            let _ = declared_size(&jpeg[..n.min(jpeg.len())]);
        }
        assert!(declared_size(&jpeg[..10]).is_err());
        assert!(declared_size(b"GIF89a").is_err());
        assert!(declared_size(&[0xff, 0xd8, 0xff, 0xda, 0, 2]).is_err());
        // A zero-length segment must not loop forever.
        assert!(declared_size(&[0xff, 0xd8, 0xff, 0xe0, 0, 0]).is_err());
        // A stuffed byte where a marker should be: libjpeg would scan past it to a
        // SOF this parser never saw, so it is refused.
        assert!(declared_size(&[0xff, 0xd8, 0xff, 0x00, 0, 4, 0xff, 0xc0]).is_err());
    }
}
