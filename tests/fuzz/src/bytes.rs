//! Turning fuzz bytes into inputs: segments of a multi-file input, a cursor of numbers,
//! and messages in their shared-memory layout.

use shared_types::messages::{
    DetectionMsg, EstimateMsg, FrameHeader, ObservationEntry, ObservationSetMsg,
};

/// Separates the files (or messages) of one input.
pub const SEPARATOR: &[u8] = b"\n%%\n";

/// The parts of `data` between [`SEPARATOR`]s.
pub fn segments(data: &[u8]) -> Vec<&[u8]> {
    let mut out = Vec::new();
    let mut rest = data;
    while let Some(i) = rest.windows(SEPARATOR.len()).position(|w| w == SEPARATOR) {
        out.push(&rest[..i]);
        rest = &rest[i + SEPARATOR.len()..];
    }
    out.push(rest);
    out
}

/// Reads numbers from the front of the input; past its end everything is zero.
pub struct Cursor<'a> {
    rest: &'a [u8],
}

impl<'a> Cursor<'a> {
    pub fn new(data: &'a [u8]) -> Self {
        Self { rest: data }
    }

    pub fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }

    /// The next `n` bytes (fewer at the end).
    pub fn take(&mut self, n: usize) -> &'a [u8] {
        let (head, tail) = self.rest.split_at(n.min(self.rest.len()));
        self.rest = tail;
        head
    }

    pub fn u8(&mut self) -> u8 {
        self.take(1).first().copied().unwrap_or(0)
    }

    pub fn u64(&mut self) -> u64 {
        let mut b = [0u8; 8];
        let got = self.take(8);
        b[..got.len()].copy_from_slice(got);
        u64::from_le_bytes(b)
    }

    /// A message of type `T` from the next `size_of::<T>()` bytes (zero-padded).
    pub fn message<T: AnyBits>(&mut self) -> T {
        message(self.take(std::mem::size_of::<T>()))
    }
}

/// Message types in which every bit pattern is a valid value: `#[repr(C)]` structs of
/// integers, floats and arrays of them, with no padding (their layout tests pin the
/// sizes). This is what shared memory hands a service.
///
/// # Safety
/// Implement only for such types.
pub unsafe trait AnyBits: Copy + Default {}

// SAFETY: each is #[repr(C)] with only u8/u32/u64/f64 fields and arrays of them (or of
// other AnyBits structs), explicit `_reserved` fields and no implicit padding.
unsafe impl AnyBits for FrameHeader {}
// SAFETY: as above.
unsafe impl AnyBits for DetectionMsg {}
// SAFETY: as above.
unsafe impl AnyBits for ObservationEntry {}
// SAFETY: as above.
unsafe impl AnyBits for ObservationSetMsg {}
// SAFETY: as above.
unsafe impl AnyBits for EstimateMsg {}

/// `bytes` (zero-padded or cut to the size of `T`) read as a `T`.
pub fn message<T: AnyBits>(bytes: &[u8]) -> T {
    let mut value = T::default();
    let n = bytes.len().min(std::mem::size_of::<T>());
    // SAFETY: `T: AnyBits`, so any bytes make a valid `T`; at most size_of::<T>() bytes
    // are copied into `value`, and `bytes` cannot overlap a local.
    unsafe {
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), (&mut value as *mut T).cast::<u8>(), n);
    }
    value
}

/// The bytes of a message (the seed writer's inverse of [`message`]).
pub fn message_bytes<T: AnyBits>(value: &T) -> Vec<u8> {
    // SAFETY: `T: AnyBits` has no padding, so all size_of::<T>() bytes are initialised.
    unsafe {
        std::slice::from_raw_parts((value as *const T).cast::<u8>(), std::mem::size_of::<T>())
    }
    .to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_round_trip_through_bytes() {
        let h = FrameHeader {
            seq: 7,
            width: 64,
            t_s: 1.5,
            ..Default::default()
        };
        assert_eq!(message::<FrameHeader>(&message_bytes(&h)), h);
        let short: FrameHeader = message(&[1, 0]);
        assert_eq!(short.seq, 1);
    }

    #[test]
    fn segments_split_on_the_separator() {
        let data = [b"a".as_slice(), SEPARATOR, b"", SEPARATOR, b"bc"].concat();
        assert_eq!(segments(&data), vec![&b"a"[..], &b""[..], &b"bc"[..]]);
        assert_eq!(segments(b"x"), vec![&b"x"[..]]);
    }
}
