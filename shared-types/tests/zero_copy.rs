//! Proof of zero copy: the bytes a frame subscriber reads are the very bytes the
//! publisher wrote, in the same shared-memory file at the same offset.
//!
//! Two iceoryx2 nodes map the data segment separately, so the two virtual addresses
//! differ; what must match is the backing file (device, inode) and the offset inside
//! it, read from /proc/self/maps. A copy anywhere would land in different memory.

use shared_types::conventions::Uav;
use shared_types::messages::{FrameHeader, PixelFormat};
use shared_types::service_names::new_run_id;
use shared_types::transport::Endpoint;

/// (backing file, offset in that file) of the mapping holding `addr`.
fn backing(addr: usize) -> (String, u64) {
    let maps = std::fs::read_to_string("/proc/self/maps").unwrap();
    for line in maps.lines() {
        // start-end perms offset dev inode path
        let f: Vec<&str> = line.split_whitespace().collect();
        let (range, offset, dev, inode) = (f[0], f[2], f[3], f[4]);
        let path = f.get(5).copied().unwrap_or("");
        let (start, end) = range.split_once('-').unwrap();
        let start = usize::from_str_radix(start, 16).unwrap();
        let end = usize::from_str_radix(end, 16).unwrap();
        if (start..end).contains(&addr) {
            let file_offset = u64::from_str_radix(offset, 16).unwrap() + (addr - start) as u64;
            return (format!("{dev} {inode} {path}"), file_offset);
        }
    }
    panic!("address {addr:#x} is in no mapping");
}

#[test]
fn subscriber_reads_the_publishers_shared_memory() {
    let run = new_run_id();
    let producer = Endpoint::new(&run, "zc-pub").unwrap();
    let consumer = Endpoint::new(&run, "zc-sub").unwrap();
    let (w, h) = (640u32, 480u32);
    let len = (w * h * 3) as usize;
    let subscriber = consumer.frame_subscriber(Uav::Left).unwrap();
    let publisher = producer.frame_publisher(Uav::Left, len).unwrap();

    let mut sample = publisher.loan_slice(len).unwrap();
    for (i, b) in sample.payload_mut().iter_mut().enumerate() {
        *b = (i % 253) as u8;
    }
    *sample.user_header_mut() = FrameHeader {
        seq: 7,
        width: w,
        height: h,
        stride: w * 3,
        pixel_format: PixelFormat::Bgr8 as u32,
        ..Default::default()
    };
    let written_at = backing(sample.payload().as_ptr() as usize);
    sample.send().unwrap();

    let received = subscriber.receive().unwrap().expect("a frame");
    assert_eq!(received.user_header().seq, 7);
    let read_at = backing(received.payload().as_ptr() as usize);
    assert!(
        written_at.0.contains("/dev/shm/"),
        "not shared memory: {written_at:?}"
    );
    assert_eq!(
        read_at, written_at,
        "the subscriber's pixels are not the publisher's"
    );
    assert!(received
        .payload()
        .iter()
        .enumerate()
        .all(|(i, &b)| b == (i % 253) as u8));
}
