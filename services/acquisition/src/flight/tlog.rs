//! MAVLink telemetry logs (`.tlog`, what QGroundControl and MAVProxy record): each
//! message is an 8-byte big-endian timestamp (µs since the Unix epoch, when the ground
//! station received it) followed by the MAVLink 1 or 2 frame. Frames are decoded by the
//! `mavlink` crate (common dialect, CRC checked).
//!
//! A log is read whole and never refused for its content: a frame with a bad CRC is
//! skipped by its length (`crc_errors`), bytes that are not a frame are skipped until the
//! next one (`resyncs`), and a frame cut by the end of the file is dropped
//! (`truncated`). Only ATTITUDE, GLOBAL_POSITION_INT, GPS_RAW_INT and
//! GIMBAL_DEVICE_ATTITUDE_STATUS are kept; the time of a sample is the autopilot's own
//! clock in the message (`time_boot_ms`, `time_usec`), not the receive time, so link
//! latency does not enter the alignment.

use mavlink::dialects::common::{
    GimbalDeviceFlags, MavMessage, ATTITUDE_DATA, GIMBAL_DEVICE_ATTITUDE_STATUS_DATA,
    GLOBAL_POSITION_INT_DATA, GPS_RAW_INT_DATA,
};
use mavlink::{MavHeader, MavlinkReader, MavlinkVersion, Message};
use std::io::Write;

const MAGIC_V1: u8 = 0xfe;
const MAGIC_V2: u8 = 0xfd;
/// MAVLink 2's incompatibility flag: the frame carries a 13-byte signature.
const SIGNED: u8 = 0x01;

/// One telemetry sample, on the autopilot's clock (seconds since its boot).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NavSample {
    /// Roll, pitch, yaw in radians (ATTITUDE: NED, Z-Y-X as docs/conventions.md).
    Attitude { t_s: f64, rpy_rad: [f64; 3] },
    /// WGS84 degrees and metres (GLOBAL_POSITION_INT, or GPS_RAW_INT as fallback).
    Position {
        t_s: f64,
        lat_deg: f64,
        lon_deg: f64,
        alt_m: f64,
        from_gps_raw: bool,
    },
    /// The camera gimbal's attitude (GIMBAL_DEVICE_ATTITUDE_STATUS): roll, pitch, yaw
    /// in radians, Z-Y-X, of the gimbal frame G (recording format v2: the camera looks
    /// along G's x) relative to the body, or, with `earth_frame`, to NED (the
    /// message's YAW_IN_EARTH_FRAME flag, or YAW_LOCK without either frame flag).
    Gimbal {
        t_s: f64,
        rpy_rad: [f64; 3],
        earth_frame: bool,
    },
}

impl NavSample {
    pub fn t_s(&self) -> f64 {
        match self {
            NavSample::Attitude { t_s, .. }
            | NavSample::Position { t_s, .. }
            | NavSample::Gimbal { t_s, .. } => *t_s,
        }
    }
}

/// What reading a log found besides its samples.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TlogCounts {
    pub frames: u64,
    pub crc_errors: u64,
    pub resyncs: u64,
    pub truncated: u64,
    /// Messages of other types (ignored).
    pub other: u64,
}

/// The total length of the frame starting at `frame[0]`, from its header.
fn frame_len(frame: &[u8]) -> Option<usize> {
    match *frame.first()? {
        MAGIC_V1 => Some(6 + *frame.get(1)? as usize + 2),
        MAGIC_V2 => {
            let payload = *frame.get(1)? as usize;
            let signature = if frame.get(2)? & SIGNED != 0 { 13 } else { 0 };
            Some(10 + payload + 2 + signature)
        }
        _ => None,
    }
}

/// The samples of a message, if it is one dualgeo uses.
fn sample(msg: &MavMessage) -> Option<NavSample> {
    match msg {
        MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms,
            roll,
            pitch,
            yaw,
            ..
        }) => Some(NavSample::Attitude {
            t_s: *time_boot_ms as f64 / 1e3,
            rpy_rad: [*roll as f64, *pitch as f64, *yaw as f64],
        }),
        MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            time_boot_ms,
            lat,
            lon,
            alt,
            ..
        }) => Some(NavSample::Position {
            t_s: *time_boot_ms as f64 / 1e3,
            lat_deg: *lat as f64 / 1e7,
            lon_deg: *lon as f64 / 1e7,
            alt_m: *alt as f64 / 1e3,
            from_gps_raw: false,
        }),
        MavMessage::GPS_RAW_INT(GPS_RAW_INT_DATA {
            time_usec,
            lat,
            lon,
            alt,
            fix_type,
            ..
        // time_usec may be Unix time (the spec allows either): only a boot-clock time
        // lines up with ATTITUDE's.
        }) if (*fix_type as u32) >= 3 && *time_usec < 1_000_000_000_000_000 => Some(NavSample::Position {
            t_s: *time_usec as f64 / 1e6,
            lat_deg: *lat as f64 / 1e7,
            lon_deg: *lon as f64 / 1e7,
            alt_m: *alt as f64 / 1e3,
            from_gps_raw: true,
        }),
        MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
            time_boot_ms,
            q,
            flags,
            ..
        }) => {
            let [w, x, y, z] = q.map(|v| v as f64);
            let (roll, pitch, yaw) =
                nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z))
                    .euler_angles();
            let earth_frame = flags.contains(GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME)
                || (!flags.contains(GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME)
                    && flags.contains(GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_LOCK));
            Some(NavSample::Gimbal {
                t_s: *time_boot_ms as f64 / 1e3,
                rpy_rad: [roll, pitch, yaw],
                earth_frame,
            })
        }
        _ => None,
    }
}

/// GIMBAL_DEVICE_ATTITUDE_STATUS for a gimbal at `rpy_rad` (roll, pitch, yaw, Z-Y-X)
/// relative to the body (YAW_IN_VEHICLE_FRAME), at `time_boot_ms`.
pub fn gimbal_message(time_boot_ms: u32, rpy_rad: [f64; 3]) -> MavMessage {
    let [roll, pitch, yaw] = rpy_rad;
    let q = nalgebra::UnitQuaternion::from_euler_angles(roll, pitch, yaw);
    MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
        time_boot_ms,
        q: [q.w, q.i, q.j, q.k].map(|v| v as f32),
        flags: GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME,
        ..Default::default()
    })
}

/// The message ids dualgeo reads (others are skipped by their length, undecoded: the
/// common dialect does not know every autopilot's messages, and an unknown id is not
/// damage).
const GPS_RAW_INT_ID: u32 = 24;
const ATTITUDE_ID: u32 = 30;
const GLOBAL_POSITION_INT_ID: u32 = 33;
const GIMBAL_DEVICE_ATTITUDE_STATUS_ID: u32 = 285;

/// Whether dualgeo decodes messages of this id.
fn is_read(id: u32) -> bool {
    matches!(
        id,
        GPS_RAW_INT_ID | ATTITUDE_ID | GLOBAL_POSITION_INT_ID | GIMBAL_DEVICE_ATTITUDE_STATUS_ID
    )
}

/// (message id, sending system, sequence) from a frame's header.
fn header_fields(frame: &[u8]) -> Option<(u32, u8, u8)> {
    match *frame.first()? {
        MAGIC_V1 => Some((*frame.get(5)? as u32, *frame.get(3)?, *frame.get(2)?)),
        MAGIC_V2 => {
            let id = u32::from_le_bytes([*frame.get(7)?, *frame.get(8)?, *frame.get(9)?, 0]);
            Some((id, *frame.get(5)?, *frame.get(4)?))
        }
        _ => None,
    }
}

/// Decodes one MAVLink frame (exactly `frame`'s bytes), CRC checked. `None` also when
/// the frame the reader found is not the one at `frame[0]` (a chance magic byte: the
/// reader would scan on and return a later frame).
pub fn decode_frame(frame: &[u8]) -> Option<MavMessage> {
    let (id, _, seq) = header_fields(frame)?;
    let version = if frame[0] == MAGIC_V2 {
        MavlinkVersion::V2
    } else {
        MavlinkVersion::V1
    };
    let mut reader = MavlinkReader::new(frame);
    let raw = reader.read_any_raw_message::<MavMessage>().ok()?;
    let own = raw.message_id() == id
        && raw.sequence() == seq
        && raw.payload().len() == *frame.get(1)? as usize;
    if !own {
        return None;
    }
    MavMessage::parse(version, id, raw.payload()).ok()
}

/// Every sample of a tlog's bytes with its sending system, in file order, and what was
/// skipped. GPS_RAW_INT positions are kept only when the log has no
/// GLOBAL_POSITION_INT.
pub fn parse_tlog(bytes: &[u8]) -> (Vec<(u8, NavSample)>, TlogCounts) {
    let mut counts = TlogCounts::default();
    let mut samples = Vec::new();
    let mut at = 0usize;
    let mut in_sync = true;
    while at < bytes.len() {
        if at + 8 + 3 > bytes.len() {
            // Not even a timestamp and a frame header left: the log was cut.
            counts.truncated += 1;
            break;
        }
        let frame = &bytes[at + 8..];
        let Some(len) = frame_len(frame) else {
            // Not a frame here: slide one byte (one resync per lost stretch).
            if in_sync {
                counts.resyncs += 1;
                in_sync = false;
            }
            at += 1;
            continue;
        };
        if frame.len() < len {
            if in_sync {
                counts.truncated += 1;
                break;
            }
            at += 1;
            continue;
        }
        let Some((id, system, _)) = header_fields(frame) else {
            at += 1;
            continue;
        };
        if !is_read(id) {
            if in_sync {
                // Another message: skipped by its length, unchecked.
                counts.frames += 1;
                counts.other += 1;
                at += 8 + len;
            } else {
                at += 1;
            }
            continue;
        }
        match decode_frame(&frame[..len]) {
            Some(msg) => {
                in_sync = true;
                counts.frames += 1;
                match sample(&msg) {
                    Some(s) => samples.push((system, s)),
                    None => counts.other += 1,
                }
                at += 8 + len;
            }
            // In step with the records, a bad frame is skipped by its length; out of
            // step, a "magic" byte was chance and the search goes on byte by byte.
            None if in_sync => {
                counts.frames += 1;
                counts.crc_errors += 1;
                at += 8 + len;
            }
            None => at += 1,
        }
    }
    let has_global = samples.iter().any(|(_, s)| {
        matches!(
            s,
            NavSample::Position {
                from_gps_raw: false,
                ..
            }
        )
    });
    if has_global {
        samples.retain(|(_, s)| {
            !matches!(
                s,
                NavSample::Position {
                    from_gps_raw: true,
                    ..
                }
            )
        });
    }
    (samples, counts)
}

/// One MAVLink frame of a live datagram (`udpin:` telemetry).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveFrame {
    pub system: u8,
    pub component: u8,
    /// The sender's per-link sequence number (gaps are lost messages).
    pub seq: u8,
    /// The frame passed its CRC (frames of ids dualgeo does not read are not checked).
    pub crc_ok: bool,
    /// Its navigation sample, if it is a message dualgeo reads.
    pub sample: Option<NavSample>,
}

/// The frames of one UDP datagram (a sender may pack several), and whether bytes that
/// are not a frame were left over (the rest of such a datagram is dropped).
pub fn split_datagram(bytes: &[u8]) -> (Vec<LiveFrame>, bool) {
    let mut frames = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        let frame = &bytes[at..];
        let (Some(len), Some((id, system, seq))) = (frame_len(frame), header_fields(frame)) else {
            return (frames, true);
        };
        if frame.len() < len {
            return (frames, true);
        }
        let component = if frame[0] == MAGIC_V2 {
            frame[6]
        } else {
            frame[4]
        };
        let frame = &frame[..len];
        let (crc_ok, sample) = if is_read(id) {
            match decode_frame(frame) {
                Some(msg) => (true, sample(&msg)),
                None => (false, None),
            }
        } else {
            (true, None)
        };
        frames.push(LiveFrame {
            system,
            component,
            seq,
            crc_ok,
            sample,
        });
        at += len;
    }
    (frames, false)
}

/// Writes tlog records: the simulator's `--flight-out` and the tests.
pub struct TlogWriter<W: Write> {
    out: W,
    header: MavHeader,
}

impl<W: Write> TlogWriter<W> {
    /// Messages from `system_id`, component 1 (the autopilot).
    pub fn new(out: W, system_id: u8) -> Self {
        Self {
            out,
            header: MavHeader {
                system_id: system_id.into(),
                component_id: 1,
                sequence: 0,
            },
        }
    }

    /// One record: the receive time (µs since the epoch) and the MAVLink 2 frame.
    pub fn write(&mut self, receive_unix_us: u64, msg: &MavMessage) -> std::io::Result<()> {
        let mut frame = Vec::with_capacity(64);
        mavlink::write_versioned_msg(&mut frame, MavlinkVersion::V2, self.header, msg)
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        self.header.sequence = self.header.sequence.wrapping_add(1);
        self.out.write_all(&receive_unix_us.to_be_bytes())?;
        self.out.write_all(&frame)
    }

    pub fn into_inner(self) -> W {
        self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn attitude(ms: u32) -> MavMessage {
        MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: ms,
            roll: 0.1,
            pitch: -0.05,
            yaw: 1.5,
            ..Default::default()
        })
    }

    fn position(ms: u32) -> MavMessage {
        MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            time_boot_ms: ms,
            lat: 473_976_597,
            lon: 85_000_000,
            alt: 512_300,
            ..Default::default()
        })
    }

    fn log(n: u32) -> Vec<u8> {
        let mut w = TlogWriter::new(Vec::new(), 1);
        for k in 0..n {
            w.write(1_700_000_000_000_000 + k as u64 * 20_000, &attitude(k * 20))
                .unwrap();
            w.write(1_700_000_000_000_000 + k as u64 * 20_000, &position(k * 20))
                .unwrap();
        }
        w.into_inner()
    }

    #[test]
    fn a_datagram_of_several_frames_splits_into_them() {
        let mut bytes = Vec::new();
        for (seq, msg) in [(7u8, attitude(20)), (8, position(20))] {
            let h = MavHeader {
                system_id: 3,
                component_id: 1,
                sequence: seq,
            };
            mavlink::write_versioned_msg(&mut bytes, MavlinkVersion::V2, h, &msg).unwrap();
        }
        let (frames, rest) = split_datagram(&bytes);
        assert!(!rest);
        assert_eq!(frames.len(), 2);
        assert_eq!(
            (frames[0].system, frames[0].component, frames[0].seq),
            (3, 1, 7)
        );
        assert!(frames.iter().all(|f| f.crc_ok && f.sample.is_some()));
        let mut bad = bytes.clone();
        bad[12] ^= 0x55; // a payload byte of the first frame
        let (frames, _) = split_datagram(&bad);
        assert!(!frames[0].crc_ok && frames[0].sample.is_none() && frames[1].crc_ok);
        let (frames, rest) = split_datagram(&bytes[..bytes.len() - 3]);
        assert_eq!(frames.len(), 1, "a cut frame is not a frame");
        assert!(rest);
    }

    #[test]
    fn a_gimbal_attitude_reads_back_in_its_frame() {
        let mut w = TlogWriter::new(Vec::new(), 1);
        w.write(1, &gimbal_message(1500, [0.01, -0.9, 0.35]))
            .unwrap();
        let (samples, counts) = parse_tlog(&w.into_inner());
        assert_eq!((samples.len(), counts.crc_errors), (1, 0));
        let NavSample::Gimbal {
            t_s,
            rpy_rad,
            earth_frame,
        } = samples[0].1
        else {
            panic!("{samples:?}");
        };
        assert_eq!((t_s, earth_frame), (1.5, false));
        for (got, want) in rpy_rad.iter().zip([0.01, -0.9, 0.35]) {
            assert!((got - want).abs() < 1e-6, "{rpy_rad:?}");
        }
    }

    #[test]
    fn a_written_log_reads_back() {
        let (samples, counts) = parse_tlog(&log(5));
        assert_eq!(
            counts,
            TlogCounts {
                frames: 10,
                ..Default::default()
            }
        );
        assert_eq!(samples.len(), 10);
        assert!(samples.iter().all(|(system, _)| *system == 1));
        let samples: Vec<NavSample> = samples.into_iter().map(|(_, s)| s).collect();
        assert_eq!(
            samples[2],
            NavSample::Attitude {
                t_s: 0.02,
                rpy_rad: [0.1f32 as f64, -0.05f32 as f64, 1.5]
            }
        );
        match samples[3] {
            NavSample::Position { lat_deg, alt_m, .. } => {
                assert!((lat_deg - 47.3976597).abs() < 1e-9 && (alt_m - 512.3).abs() < 1e-9)
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_crc_error_skips_one_frame_and_a_cut_end_is_dropped() {
        let mut bytes = log(5);
        // Corrupt one payload byte of the third record (8 + 10 header bytes in).
        let first = 8 + frame_len(&bytes[8..]).unwrap();
        let second = first + 8 + frame_len(&bytes[first + 8..]).unwrap();
        bytes[second + 8 + 12] ^= 0x55;
        bytes.truncate(bytes.len() - 5);
        let (samples, counts) = parse_tlog(&bytes);
        assert_eq!(counts.crc_errors, 1);
        assert_eq!(counts.truncated, 1);
        assert_eq!(samples.len(), 10 - 2);
    }

    #[test]
    fn garbage_between_records_is_skipped_and_counted_once() {
        let good = log(2);
        let mut bytes = good.clone();
        bytes.extend_from_slice(&[0x00, 0x13, 0x37, 0x42, 0x99, 0x11, 0x22]);
        bytes.extend_from_slice(&good);
        let (samples, counts) = parse_tlog(&bytes);
        assert_eq!(samples.len(), 8);
        assert!(counts.resyncs >= 1);
    }

    #[test]
    fn messages_dualgeo_does_not_read_are_skipped_not_damage() {
        let mut w = TlogWriter::new(Vec::new(), 1);
        let heartbeat = MavMessage::HEARTBEAT(Default::default());
        w.write(1, &heartbeat).unwrap();
        w.write(2, &attitude(0)).unwrap();
        let mut bytes = w.into_inner();
        // An id the common dialect does not know (an autopilot's own message).
        let mut unknown = vec![0u8; 8];
        unknown.extend_from_slice(&[
            MAGIC_V2, 2, 0, 0, 7, 1, 1, 0x10, 0x27, 0, 0xaa, 0xbb, 0x12, 0x34,
        ]);
        bytes.extend_from_slice(&unknown);
        let (samples, counts) = parse_tlog(&bytes);
        assert_eq!(samples.len(), 1);
        assert_eq!((counts.other, counts.crc_errors, counts.resyncs), (2, 0, 0));
    }

    #[test]
    fn any_bytes_are_read_without_panicking() {
        let good = log(3);
        for cut in 0..good.len() {
            let _ = parse_tlog(&good[..cut]);
            let mut flipped = good.clone();
            flipped[cut] ^= 0xff;
            let _ = parse_tlog(&flipped);
        }
    }
}
