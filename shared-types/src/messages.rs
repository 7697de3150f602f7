//! Shared-memory message layouts. Every type here is `#[repr(C)]`, fixed size,
//! `ZeroCopySend` and `Default`, so iceoryx2 can place it in shared memory. Every message
//! carries `capture_ns` (CLOCK_MONOTONIC at capture) so any stage can compute its age.
//!
//! Type names are pinned with `#[type_name]` so separately built processes agree.

use crate::conventions::Attitude;
use iceoryx2::prelude::ZeroCopySend;
use nalgebra::Point3;

/// Layout of the pixels that follow a [`FrameHeader`] in a `[u8]` sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum PixelFormat {
    Gray8 = 1,
    Bgr8 = 3,
}

impl PixelFormat {
    pub fn bytes_per_pixel(self) -> u32 {
        self as u32
    }

    pub fn from_code(code: u32) -> Option<Self> {
        match code {
            1 => Some(PixelFormat::Gray8),
            3 => Some(PixelFormat::Bgr8),
            _ => None,
        }
    }
}

/// A measured navigation state as recorded (telemetry.csv): ENU metres and degrees.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::PoseSample/v1")]
pub struct PoseSample {
    pub x_m: f64,
    pub y_m: f64,
    pub z_m: f64,
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
}

impl PoseSample {
    pub fn position(&self) -> Point3<f64> {
        Point3::new(self.x_m, self.y_m, self.z_m)
    }

    pub fn attitude(&self) -> Attitude {
        Attitude::from_degrees(self.yaw_deg, self.pitch_deg, self.roll_deg)
    }

    pub fn is_finite(&self) -> bool {
        [
            self.x_m,
            self.y_m,
            self.z_m,
            self.yaw_deg,
            self.pitch_deg,
            self.roll_deg,
        ]
        .iter()
        .all(|v| v.is_finite())
    }
}

/// User header of a frame sample; the payload is `stride × height` bytes of pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::FrameHeader/v1")]
pub struct FrameHeader {
    /// Per-UAV frame index.
    pub seq: u64,
    /// CLOCK_MONOTONIC nanoseconds when the frame entered dualgeo.
    pub capture_ns: u64,
    /// Capture time on the recording's clock, seconds.
    pub t_s: f64,
    /// 0 = left, 1 = right.
    pub uav: u8,
    pub _reserved: [u8; 3],
    /// [`PixelFormat`] code.
    pub pixel_format: u32,
    pub width: u32,
    pub height: u32,
    /// Bytes per row.
    pub stride: u32,
    pub _reserved2: u32,
    /// Measured pose at capture.
    pub pose: PoseSample,
}

impl FrameHeader {
    /// Bytes of pixel payload this header describes, or `None` if inconsistent.
    pub fn payload_len(&self) -> Option<usize> {
        let format = PixelFormat::from_code(self.pixel_format)?;
        let min_stride = self.width.checked_mul(format.bytes_per_pixel())?;
        if self.stride < min_stride {
            return None;
        }
        (self.stride as usize).checked_mul(self.height as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payload_len_checks_stride() {
        let mut h = FrameHeader {
            pixel_format: PixelFormat::Bgr8 as u32,
            width: 640,
            height: 480,
            stride: 1920,
            ..Default::default()
        };
        assert_eq!(h.payload_len(), Some(1920 * 480));
        h.stride = 1000;
        assert_eq!(h.payload_len(), None);
        h.pixel_format = 7;
        assert_eq!(h.payload_len(), None);
    }

    #[test]
    fn header_layout_is_stable() {
        // 8+8+8 + 1+3+4 + 4+4+4+4 + 6·8 = 96 bytes, 8-aligned, no hidden padding.
        assert_eq!(std::mem::size_of::<FrameHeader>(), 96);
        assert_eq!(std::mem::align_of::<FrameHeader>(), 8);
    }
}
