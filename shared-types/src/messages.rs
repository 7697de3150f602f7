//! Shared-memory message layouts. Every type here is `#[repr(C)]`, fixed size,
//! `ZeroCopySend` and `Default`, so iceoryx2 can place it in shared memory. Every message
//! carries `capture_ns` (CLOCK_MONOTONIC at capture) so any stage can compute its age.
//!
//! Type names are pinned with `#[type_name]` so separately built processes agree.

use crate::conventions::{Attitude, Mount};
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

/// A camera's mount on its body ([`Mount`], recording format v2's gimbal angles of G
/// relative to the body), in degrees. The default is the nadir mount.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::MountSample/v1")]
pub struct MountSample {
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
}

impl Default for MountSample {
    fn default() -> Self {
        Self::from_mount(Mount::NADIR)
    }
}

impl MountSample {
    pub fn from_mount(mount: Mount) -> Self {
        let a = mount.0;
        Self {
            yaw_deg: a.yaw.to_degrees(),
            pitch_deg: a.pitch.to_degrees(),
            roll_deg: a.roll.to_degrees(),
        }
    }

    /// Back to radians; the nadir mount exactly for the default (so a nadir camera's
    /// attitude is taken as its body's to the last bit).
    pub fn mount(&self) -> Mount {
        if *self == Self::default() {
            Mount::NADIR
        } else {
            Mount::from_degrees(self.yaw_deg, self.pitch_deg, self.roll_deg)
        }
    }

    pub fn is_finite(&self) -> bool {
        [self.yaw_deg, self.pitch_deg, self.roll_deg]
            .iter()
            .all(|v| v.is_finite())
    }
}

/// A measured navigation state as recorded (telemetry.csv): ENU metres and degrees.
/// Once a camera's mount is applied ([`PoseSample::on_mount`]) the attitude is the
/// camera's equivalent nadir attitude and `mount` says through which mount it was
/// turned (the estimator takes the AHRS's errors off the body's angles through it);
/// a body's own sample, or a nadir camera's, has the nadir mount.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::PoseSample/v2")]
pub struct PoseSample {
    pub x_m: f64,
    pub y_m: f64,
    pub z_m: f64,
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    pub mount: MountSample,
}

impl PoseSample {
    pub fn position(&self) -> Point3<f64> {
        Point3::new(self.x_m, self.y_m, self.z_m)
    }

    pub fn attitude(&self) -> Attitude {
        Attitude::from_degrees(self.yaw_deg, self.pitch_deg, self.roll_deg)
    }

    /// The pose of a camera on `mount` when this is its body's: the same position, the
    /// attitude turned into the equivalent nadir camera's
    /// ([`Mount::equivalent_nadir_attitude`]; the yaw bias carries over).
    /// `mount` is recorded in the sample.
    pub fn on_mount(self, mount: Mount) -> PoseSample {
        let a = mount.equivalent_nadir_attitude(self.attitude());
        PoseSample {
            yaw_deg: a.yaw.to_degrees(),
            pitch_deg: a.pitch.to_degrees(),
            roll_deg: a.roll.to_degrees(),
            mount: MountSample::from_mount(mount),
            ..self
        }
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
            && self.mount.is_finite()
    }
}

/// User header of a frame sample; the payload is `stride × height` bytes of pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::FrameHeader/v5")]
pub struct FrameHeader {
    /// Per-UAV frame index (the pair index: left and right frames of one instant share it).
    pub seq: u64,
    /// CLOCK_MONOTONIC nanoseconds when the frame entered dualgeo.
    pub capture_ns: u64,
    /// CLOCK_MONOTONIC nanoseconds just before the sample was sent (transport hop start).
    pub published_ns: u64,
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
    /// The stream's segment: 0 at the start, one more wherever the stream jumps
    /// (a looped recording starting over). What assumes a continuous world (the
    /// image tracks, the keyframe rings, the filter, the other vehicles' tracks)
    /// starts over with a new segment, as for a new stream; the clock (`t_s`) and
    /// the sequence numbers go on.
    pub segment: u32,
    /// Measured pose at capture.
    pub pose: PoseSample,
    /// Pinhole intrinsics of this camera: fx, fy, cx, cy (pixels).
    pub intrinsics: [f64; 4],
    /// Lens distortion of the pixels (OpenCV's k1, k2, p1, p2, k3; zeros = pinhole).
    /// Matching undistorts the detection and the keypoints with it
    /// ([`crate::lens::Distortion`]).
    pub distortion: [f64; 5],
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

/// Most other objects a [`DetectionMsg`] carries besides the target.
pub const MAX_CANDIDATES: usize = 16;

/// An object a detector found in a frame besides the target: every blob of the
/// configured colour, every mover (several targets).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::Candidate/v1")]
pub struct Candidate {
    /// x, y, width, height, pixels.
    pub bbox: [f64; 4],
    /// Its point (u, v), pixels, as the target's `centre`.
    pub centre: [f64; 2],
    pub confidence: f32,
    /// The frame's colour at `centre` (BGR, median of 3 × 3): appearance for
    /// associating it across the two views.
    pub bgr: [u8; 3],
    pub _reserved: u8,
}

/// The detector's answer for one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::DetectionMsg/v2")]
pub struct DetectionMsg {
    pub seq: u64,
    pub capture_ns: u64,
    pub published_ns: u64,
    pub t_s: f64,
    /// 0 = left, 1 = right.
    pub uav: u8,
    /// 1 when the target was found; the fields below are meaningful only then.
    pub found: u8,
    /// Valid entries of `candidates`.
    pub candidate_count: u8,
    pub _reserved: u8,
    /// Candidates found beyond [`MAX_CANDIDATES`] and left out (the smallest).
    pub candidates_dropped: u32,
    /// x, y, width, height, pixels.
    pub bbox: [f64; 4],
    /// Target pixel (u, v).
    pub centre: [f64; 2],
    pub confidence: f64,
    /// The other objects in the frame (the target is not among them).
    pub candidates: [Candidate; MAX_CANDIDATES],
}

impl DetectionMsg {
    /// The valid candidates.
    pub fn candidates(&self) -> &[Candidate] {
        &self.candidates[..usize::from(self.candidate_count).min(MAX_CANDIDATES)]
    }
}

/// One image of an observation set: the measured pose and the target's pixel.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::ObservationEntry/v5")]
pub struct ObservationEntry {
    /// 0 = left, 1 = right.
    pub uav: u8,
    /// Bit s set: `rotation[s]` holds a measurement (past images only).
    pub rotation_valid: u8,
    pub _reserved: [u8; 6],
    /// The image's frame sequence number (with `uav`, its identity across sets: the
    /// temporal estimator recognises a reused keyframe by it).
    pub frame_seq: u64,
    /// The image's capture time, seconds, on the clock of the set's `t_s` (a past
    /// image's is earlier: the temporal estimator ages its correlated pose error).
    pub t_s: f64,
    pub pose: PoseSample,
    /// (u, v), pixels: the detection (current images) or the epipolar transfer (past).
    pub pixel: [f64; 2],
    /// fx, fy, cx, cy.
    pub intrinsics: [f64; 4],
    /// A past image's rotation from the current left (`[0]`) and right (`[1]`) camera,
    /// as the images measure it (matching's ground-plane homography, decomposed):
    /// `X_past = R X_current` in camera axes, as a rotation vector (axis × angle,
    /// radians). Valid where bit s of `rotation_valid` is set.
    pub rotation: [[f64; 3]; 2],
}

impl ObservationEntry {
    /// `rotation[side]`, if measured.
    pub fn rotation_from(&self, side: usize) -> Option<[f64; 3]> {
        (side < 2 && self.rotation_valid & (1 << side) != 0).then(|| self.rotation[side])
    }
}

/// Most images an observation set carries (N ≤ 16 per UAV).
pub const MAX_OBSERVATIONS: usize = 32;

/// Most other targets an observation set carries besides the target.
pub const MAX_OTHER_TARGETS: usize = 8;

/// Another vehicle both current images show (several targets): its pixels in the
/// current images (associated across the views) and transferred into the set's past
/// images through the same fundamental matrices as the target's. Pixels are ideal
/// pinhole ones, as the entries'.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::OtherTarget/v1")]
pub struct OtherTarget {
    /// In the current left and right images (`entries[0]`, `entries[1]`).
    pub current: [[f64; 2]; 2],
    /// `past[k]` is its pixel in `entries[2 + k]`, valid where bit k of `past_valid`
    /// is set (a transfer can fail for one vehicle and not another).
    pub past: [[f64; 2]; MAX_OBSERVATIONS - 2],
    pub past_valid: u32,
    /// Its colour in the current left and right images (BGR).
    pub bgr: [[u8; 3]; 2],
    pub _reserved: [u8; 6],
}

impl Default for OtherTarget {
    fn default() -> Self {
        Self {
            current: [[0.0; 2]; 2],
            past: [[0.0; 2]; MAX_OBSERVATIONS - 2],
            past_valid: 0,
            bgr: [[0; 3]; 2],
            _reserved: [0; 6],
        }
    }
}

impl OtherTarget {
    /// Its pixel in past image `k` (`entries[2 + k]`), if transferred.
    pub fn past_pixel(&self, k: usize) -> Option<[f64; 2]> {
        (k < MAX_OBSERVATIONS - 2 && self.past_valid & (1 << k) != 0).then(|| self.past[k])
    }
}

/// The white noise of one UAV's pose samples, as matching measures it over the frames
/// it is given (`geolocation::telemetry_noise`): the σ of each sample's distance from
/// the chord through its neighbours. `chords` 0: not measured (yet).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::PoseNoise/v1")]
pub struct PoseNoise {
    /// σ̂ of x, y, z (m) and yaw, pitch, roll (degrees).
    pub sigma: [f64; 6],
    /// The chords' mean time step, seconds.
    pub mean_step_s: f64,
    /// Chords it is measured over.
    pub chords: u32,
    pub _reserved: u32,
}

/// Matching's output for one stereo pair: `entries[0]` is the current left image,
/// `entries[1]` the current right one, then `count − 2` past images.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::ObservationSetMsg/v12")]
pub struct ObservationSetMsg {
    /// Index of this set among the sets matching published (gaps = sets lost).
    pub set_seq: u64,
    pub pair_seq: u64,
    pub capture_ns: u64,
    pub published_ns: u64,
    pub t_s: f64,
    pub count: u32,
    /// Past images that gave no corresponding point.
    pub rejected_past: u32,
    /// The stream segment of the pair ([`FrameHeader::segment`]).
    pub segment: u32,
    /// [`ObservationSetMsg::REFUSED_TWO_VEHICLES`] (1): the two current detections are
    /// two vehicles and could not be mended (matching's pair check): the set holds the
    /// current images only, and no estimate may take its rays (the filter publishes its
    /// prediction). [`ObservationSetMsg::TARGET_UNSEEN`] (2): a current image has no
    /// target detection (hidden, say): no target estimate; either no entries (the
    /// other vehicles' tracks are predicted) or, when both images show other vehicles,
    /// the images as entries with the target's pixels (0, 0), never read, and the
    /// vehicles in `others` (geolocation locates them alone). 0 otherwise.
    pub refused: u32,
    pub entries: [ObservationEntry; MAX_OBSERVATIONS],
    /// Valid entries of `others`.
    pub other_count: u32,
    /// Other vehicles associated across the views but left out for room.
    pub others_dropped: u32,
    /// Other vehicles both current images show, through the same images.
    pub others: [OtherTarget; MAX_OTHER_TARGETS],
    /// Each UAV's (left, right) pose-sample noise up to this pair.
    pub pose_noise: [PoseNoise; 2],
}

impl Default for ObservationSetMsg {
    fn default() -> Self {
        Self {
            set_seq: 0,
            pair_seq: 0,
            capture_ns: 0,
            published_ns: 0,
            t_s: 0.0,
            count: 0,
            rejected_past: 0,
            segment: 0,
            refused: 0,
            entries: [ObservationEntry::default(); MAX_OBSERVATIONS],
            other_count: 0,
            others_dropped: 0,
            others: [OtherTarget::default(); MAX_OTHER_TARGETS],
            pose_noise: [PoseNoise::default(); 2],
        }
    }
}

impl ObservationSetMsg {
    /// `refused`: the current detections are two vehicles.
    pub const REFUSED_TWO_VEHICLES: u32 = 1;
    /// `refused`: a current image has no target detection.
    pub const TARGET_UNSEEN: u32 = 2;

    /// The filled entries (`count` clamped to the array).
    pub fn entries(&self) -> &[ObservationEntry] {
        &self.entries[..(self.count as usize).min(MAX_OBSERVATIONS)]
    }

    /// The valid other targets.
    pub fn others(&self) -> &[OtherTarget] {
        &self.others[..(self.other_count as usize).min(MAX_OTHER_TARGETS)]
    }
}

/// Most other vehicles' tracks an [`EstimateMsg`] carries.
pub const MAX_TRACKS: usize = 8;

/// Another vehicle's confirmed track at one pair (several targets).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::TrackEstimate/v1")]
pub struct TrackEstimate {
    /// Stable while the track lives; from 1 (0 is the target).
    pub id: u32,
    /// 1 tracking (a fix this pair), 2 coasting (its prediction), as the target's
    /// `quality`.
    pub quality: u32,
    /// (x, y, z), world ENU metres.
    pub position: [f64; 3],
    /// Covariance of (x, y), m², row-major.
    pub covariance_xy: [f64; 4],
    /// Standard error of z, metres.
    pub altitude_std_error_m: f64,
    /// (east, north), m/s.
    pub velocity_mps: [f64; 2],
}

/// Geolocation's output for one stereo pair.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("dualgeo::EstimateMsg/v3")]
pub struct EstimateMsg {
    pub pair_seq: u64,
    pub capture_ns: u64,
    pub published_ns: u64,
    pub t_s: f64,
    /// 0 = estimate valid; otherwise a [`crate::messages::EstimateStatus`] code and the
    /// numeric fields are zero.
    pub status: u32,
    pub images_used: u32,
    pub iterations: u32,
    pub converged: u32,
    /// (x, y, z), world ENU metres.
    pub position: [f64; 3],
    /// (δψ_L, δψ_R), degrees: measured yaw minus true yaw.
    pub yaw_bias_deg: [f64; 2],
    /// Covariance of (x, y, δψ_L, δψ_R), m² and rad², row-major.
    pub covariance: [f64; 16],
    /// Standard error of z, metres.
    pub altitude_std_error_m: f64,
    /// Target velocity east, north (m/s), from the temporal filter; NaN when the method
    /// keeps no state (MAVLink's "NaN if unknown").
    pub velocity_mps: [f64; 2],
    /// 1σ horizontal velocity accuracy √(σ_vx² + σ_vy²), m/s; NaN when unknown.
    pub velocity_acc_mps: f64,
    /// Distance from the left UAV's current (measured) position to the target, m.
    pub range_m: f64,
    /// How far the estimate can be trusted (issue #23): 0 converging (the yaw biases
    /// are not yet known; the accuracy is large and honest), 1 tracking, 2 coasting
    /// (no ray of the current pair taken: the filter's prediction). 64 bits: the
    /// message has no padding.
    pub quality: u64,
    /// Valid entries of `tracks` (64 bits: no padding).
    pub track_count: u64,
    /// The other vehicles' confirmed tracks, the yaw biases shared with the target.
    pub tracks: [TrackEstimate; MAX_TRACKS],
}

impl EstimateMsg {
    /// The valid tracks of other vehicles.
    pub fn tracks(&self) -> &[TrackEstimate] {
        &self.tracks[..(self.track_count as usize).min(MAX_TRACKS)]
    }
}

/// Why an [`EstimateMsg`] carries no estimate.
impl EstimateMsg {
    /// Why an estimate may not be written out after one at `last_t_s`: `out_of_order`
    /// (not newer) or `non_finite` (an `Ok` status with a non-finite time, position or
    /// bias). `None`: it may. The supervisor's guard on what it reads.
    pub fn refusal(&self, last_t_s: Option<f64>) -> Option<&'static str> {
        // Whatever the status: a non-finite time would become the "last" one and
        // refuse everything after it.
        if !self.t_s.is_finite() {
            return Some("non_finite");
        }
        if last_t_s.is_some_and(|t| self.t_s.partial_cmp(&t) != Some(std::cmp::Ordering::Greater)) {
            return Some("out_of_order");
        }
        let finite = self.t_s.is_finite()
            && self
                .position
                .iter()
                .chain(&self.yaw_bias_deg)
                .all(|v| v.is_finite());
        (self.status == EstimateStatus::Ok as u32 && !finite).then_some("non_finite")
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum EstimateStatus {
    Ok = 0,
    /// The estimator rejected the observation set (reason in the geolocation log and
    /// counters).
    Rejected = 1,
    /// The observation set itself was malformed (count, non-finite values).
    BadInput = 2,
    /// An estimate was made but withheld: its h_acc was above `[estimator]
    /// max_h_acc_m`.
    Withheld = 3,
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
    fn message_sizes_are_fixed() {
        assert_eq!(std::mem::size_of::<Candidate>(), 56);
        assert_eq!(
            std::mem::size_of::<DetectionMsg>(),
            96 + 56 * MAX_CANDIDATES
        );
        // 4·8 + 4·4 + 3·8 + 2·8 + 16·8 + 8 + 2·8 + 8 + 8 + 8: no padding (the fuzz
        // targets read it from arbitrary bytes).
        assert_eq!(std::mem::size_of::<TrackEstimate>(), 88);
        assert_eq!(
            std::mem::size_of::<EstimateMsg>(),
            264 + 8 + 88 * MAX_TRACKS
        );
        // The pose: 6·8 + the mount's 3·8.
        assert_eq!(std::mem::size_of::<PoseSample>(), 72);
        assert_eq!(std::mem::size_of::<ObservationEntry>(), 192);
        assert_eq!(std::mem::size_of::<OtherTarget>(), 32 + 16 * 30 + 16);
        assert_eq!(std::mem::size_of::<PoseNoise>(), 6 * 8 + 8 + 4 + 4);
        assert_eq!(
            std::mem::size_of::<ObservationSetMsg>(),
            56 + 192 * MAX_OBSERVATIONS + 8 + 528 * MAX_OTHER_TARGETS + 2 * 64
        );
        let set = ObservationSetMsg {
            count: 99,
            ..Default::default()
        };
        assert_eq!(set.entries().len(), MAX_OBSERVATIONS);
    }

    #[test]
    fn the_supervisor_refuses_late_and_non_finite_estimates() {
        let ok = EstimateMsg {
            t_s: 2.0,
            ..Default::default()
        };
        assert_eq!(ok.refusal(None), None);
        assert_eq!(ok.refusal(Some(1.0)), None);
        assert_eq!(ok.refusal(Some(2.0)), Some("out_of_order"));
        let nan_time = EstimateMsg {
            t_s: f64::NAN,
            ..ok
        };
        assert_eq!(nan_time.refusal(Some(1.0)), Some("non_finite"));
        assert_eq!(nan_time.refusal(None), Some("non_finite"));
        let rejected_inf_time = EstimateMsg {
            t_s: f64::INFINITY,
            status: EstimateStatus::Rejected as u32,
            ..ok
        };
        assert_eq!(rejected_inf_time.refusal(None), Some("non_finite"));
        let nan_position = EstimateMsg {
            position: [0.0, f64::NAN, 0.0],
            ..ok
        };
        assert_eq!(nan_position.refusal(None), Some("non_finite"));
        let rejected = EstimateMsg {
            status: EstimateStatus::Rejected as u32,
            ..nan_position
        };
        assert_eq!(rejected.refusal(None), None);
    }

    #[test]
    fn header_layout_is_stable() {
        // 8+8+8+8 + 1+3+4 + 4+4+4+4 + (6+3)·8 (pose and mount) + 4·8 + 5·8 (distortion)
        // = 200 bytes, 8-aligned, no hidden padding.
        assert_eq!(std::mem::size_of::<FrameHeader>(), 200);
        assert_eq!(std::mem::align_of::<FrameHeader>(), 8);
    }
}
