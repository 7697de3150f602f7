//! The iceoryx2 topology every dualgeo process shares: which services exist, their
//! quality-of-service settings, and one place that opens them. Only the service shells
//! (and the supervisor) use this module; the libraries never see iceoryx2.
//!
//! Data services (publish-subscribe), all under `dualgeo/<run-id>/`:
//!
//! | service | payload | publisher → subscribers |
//! | --- | --- | --- |
//! | `frames/left`, `frames/right` | `[u8]` pixels + [`FrameHeader`] | acquisition → detection, matching |
//! | `detections` | [`DetectionMsg`] | detection → matching |
//! | `observations` | [`ObservationSetMsg`] | matching → geolocation |
//! | `estimates` | [`EstimateMsg`] | geolocation → supervisor |
//!
//! Wake-ups (event services `wake/<stage>`): a producer notifies each consumer *stage*
//! after sending, and each stage waits on its one listener in a WaitSet, then drains all
//! its subscribers. No polling, no sleeps.
//!
//! Overflow: every data service has safe overflow on. A subscriber that falls behind
//! loses its *oldest* queued sample; stages count the loss from sequence gaps. A
//! publisher never blocks: a failed loan is counted as a drop at the source.

use crate::conventions::Uav;
use crate::messages::FrameHeader;
use crate::service_names::{service_name, Topic};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use std::fmt::Debug;

pub type Ipc = ipc::Service;
pub type FramePublisher = Publisher<Ipc, [u8], FrameHeader>;
pub type FrameSubscriber = Subscriber<Ipc, [u8], FrameHeader>;
pub type MsgPublisher<T> = Publisher<Ipc, T, ()>;
pub type MsgSubscriber<T> = Subscriber<Ipc, T, ()>;

/// Frame services: at most this many subscribers (detection, matching, one spare for a
/// monitor or a test).
pub const FRAME_MAX_SUBSCRIBERS: usize = 3;
/// Frames queued per subscriber before the oldest is overwritten.
pub const FRAME_SUBSCRIBER_BUFFER: usize = 2;
/// Frames one subscriber may hold at once (matching holds a left and a right frame).
pub const FRAME_MAX_BORROWED: usize = 2;
/// Frames the publisher may have on loan at once.
pub const FRAME_MAX_LOANED: usize = 2;

/// Samples in one frame publisher's shared-memory segment (iceoryx2's formula:
/// subscribers × (buffer + borrowed) + history + loaned).
pub const FRAME_SEGMENT_SAMPLES: usize =
    FRAME_MAX_SUBSCRIBERS * (FRAME_SUBSCRIBER_BUFFER + FRAME_MAX_BORROWED) + FRAME_MAX_LOANED;

/// Shared memory of one frame service for frames of `frame_bytes`: samples × (pixels +
/// 48-byte system header + the frame header), rounded.
pub fn frame_segment_bytes(frame_bytes: usize) -> usize {
    FRAME_SEGMENT_SAMPLES * (frame_bytes + 48 + std::mem::size_of::<FrameHeader>())
}

/// Event id acquisition sends to the supervisor's wake service at the end of the stream
/// (other producers use the default id 0).
pub const END_OF_STREAM_EVENT: usize = 1;

/// Small-message services: queue depth per subscriber.
pub const MESSAGE_SUBSCRIBER_BUFFER: usize = 8;
/// Queue depth of `estimates`, whose consumers (the supervisor's outputs, MCAP,
/// detection's gate) run unthrottled by `--rate max`'s flow control (matching
/// acknowledges a pair once it is matched). Eight was measured short: two replays run
/// side by side on two cores lost one estimate each at the starved supervisor in 2 of
/// 16 runs, so track.csv lacked that pair. 64 is a second at the replay's pace, ~62 KB
/// per subscriber. (`observations` stays at 8: 64 of its 8 KB sets let a backlog at
/// the filter's start touch up to 0.5 MB more of geolocation's shared memory, which the
/// soak test's flat-memory check saw as a 2.4 % rise of its floor.)
pub const ESTIMATE_SUBSCRIBER_BUFFER: usize = 64;
pub const MESSAGE_MAX_SUBSCRIBERS: usize = 4;

/// A stage that is woken by its producers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Woken by matching's pair acknowledgements (flow control of `--rate max`).
    Acquisition,
    Detection,
    Matching,
    Geolocation,
    Supervisor,
}

impl Stage {
    pub fn name(self) -> &'static str {
        match self {
            Stage::Acquisition => "acquisition",
            Stage::Detection => "detection",
            Stage::Matching => "matching",
            Stage::Geolocation => "geolocation",
            Stage::Supervisor => "supervisor",
        }
    }
}

#[derive(Debug, thiserror::Error)]
#[error("iceoryx2: {what}: {detail}")]
pub struct TransportError {
    pub what: String,
    pub detail: String,
}

fn err(what: impl Into<String>) -> impl FnOnce(&dyn Debug) -> TransportError {
    let what = what.into();
    move |e| TransportError {
        what,
        detail: format!("{e:?}"),
    }
}

macro_rules! tr {
    ($e:expr, $what:expr) => {
        $e.map_err(|e| err($what)(&e))
    };
}

/// One process's handle on the run's services.
pub struct Endpoint {
    pub node: Node<Ipc>,
    run_id: String,
}

impl Endpoint {
    /// A node named `<process>` for the run `run_id`.
    pub fn new(run_id: &str, process: &str) -> Result<Self, TransportError> {
        let name = tr!(NodeName::new(&format!("dualgeo-{process}")), "node name")?;
        let node = tr!(
            // The built-in defaults, explicitly: every process must use the same
            // config, and no config file on the host may change it.
            NodeBuilder::new()
                .name(&name)
                .config(&Config::default())
                .create::<Ipc>(),
            format!("create node {process}")
        )?;
        // iceoryx2 installs its SIGINT/SIGTERM handler lazily, at the first wait. A
        // process killed by SIGTERM before that would die instead of stopping cleanly
        // (seen: a restarted acquisition rendering behind its clock never waited), so
        // install it now. A request that already arrived is seen at the next wait.
        let _ = node.wait(std::time::Duration::ZERO);
        Ok(Self {
            node,
            run_id: run_id.to_string(),
        })
    }

    pub fn run_id(&self) -> &str {
        &self.run_id
    }

    fn service(&self, suffix: &str) -> Result<ServiceName, TransportError> {
        tr!(
            ServiceName::new(&format!("dualgeo/{}/{suffix}", self.run_id)),
            "service name"
        )
    }

    fn frames(
        &self,
        uav: Uav,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, [u8], FrameHeader>,
        TransportError,
    > {
        let name = tr!(
            ServiceName::new(&service_name(&self.run_id, Topic::Frames(uav))),
            "service name"
        )?;
        tr!(
            self.node
                .service_builder(&name)
                .publish_subscribe::<[u8]>()
                .user_header::<FrameHeader>()
                .max_publishers(1)
                .max_subscribers(FRAME_MAX_SUBSCRIBERS)
                .subscriber_max_buffer_size(FRAME_SUBSCRIBER_BUFFER)
                .subscriber_max_borrowed_samples(FRAME_MAX_BORROWED)
                .history_size(0)
                .enable_safe_overflow(true)
                .open_or_create(),
            format!("open frames/{}", uav.name())
        )
    }

    /// The frame publisher of one UAV for frames of `frame_bytes` (fixed-size segment).
    pub fn frame_publisher(
        &self,
        uav: Uav,
        frame_bytes: usize,
    ) -> Result<FramePublisher, TransportError> {
        tr!(
            self.frames(uav)?
                .publisher_builder()
                .initial_max_slice_len(frame_bytes)
                .max_loaned_samples(FRAME_MAX_LOANED)
                .create(),
            "frame publisher"
        )
    }

    pub fn frame_subscriber(&self, uav: Uav) -> Result<FrameSubscriber, TransportError> {
        tr!(
            self.frames(uav)?.subscriber_builder().create(),
            "frame subscriber"
        )
    }

    fn messages<T: Debug + ZeroCopySend + 'static>(
        &self,
        topic: Topic,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, T, ()>,
        TransportError,
    > {
        let name = tr!(
            ServiceName::new(&service_name(&self.run_id, topic)),
            "service name"
        )?;
        tr!(
            self.node
                .service_builder(&name)
                .publish_subscribe::<T>()
                .max_publishers(1)
                .max_subscribers(MESSAGE_MAX_SUBSCRIBERS)
                .subscriber_max_buffer_size(match topic {
                    Topic::Estimates => ESTIMATE_SUBSCRIBER_BUFFER,
                    _ => MESSAGE_SUBSCRIBER_BUFFER,
                })
                .subscriber_max_borrowed_samples(2)
                .history_size(0)
                .enable_safe_overflow(true)
                .open_or_create(),
            format!("open {topic:?}")
        )
    }

    pub fn publisher<T: Debug + ZeroCopySend + 'static>(
        &self,
        topic: Topic,
    ) -> Result<MsgPublisher<T>, TransportError> {
        tr!(
            self.messages::<T>(topic)?.publisher_builder().create(),
            format!("{topic:?} publisher")
        )
    }

    pub fn subscriber<T: Debug + ZeroCopySend + 'static>(
        &self,
        topic: Topic,
    ) -> Result<MsgSubscriber<T>, TransportError> {
        tr!(
            self.messages::<T>(topic)?.subscriber_builder().create(),
            format!("{topic:?} subscriber")
        )
    }

    /// Subscribers currently connected to a message service.
    pub fn subscriber_count<T: Debug + ZeroCopySend + 'static>(
        &self,
        topic: Topic,
    ) -> Result<usize, TransportError> {
        Ok(self
            .messages::<T>(topic)?
            .dynamic_config()
            .number_of_subscribers())
    }

    /// Subscribers currently connected to a UAV's frame service.
    pub fn frame_subscriber_count(&self, uav: Uav) -> Result<usize, TransportError> {
        Ok(self.frames(uav)?.dynamic_config().number_of_subscribers())
    }

    fn wake(
        &self,
        stage: Stage,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<Ipc>, TransportError> {
        let name = self.service(&format!("wake/{}", stage.name()))?;
        tr!(
            self.node.service_builder(&name).event().open_or_create(),
            format!("open wake/{}", stage.name())
        )
    }

    /// The listener a stage waits on.
    pub fn listener(&self, stage: Stage) -> Result<Listener<Ipc>, TransportError> {
        tr!(
            self.wake(stage)?.listener_builder().create(),
            format!("{} listener", stage.name())
        )
    }

    /// A notifier that wakes `stage`.
    pub fn notifier(&self, stage: Stage) -> Result<Notifier<Ipc>, TransportError> {
        tr!(
            self.wake(stage)?.notifier_builder().create(),
            format!("{} notifier", stage.name())
        )
    }

    /// Listeners attached to a stage's wake service (1 once that stage is up).
    pub fn listener_count(&self, stage: Stage) -> Result<usize, TransportError> {
        Ok(self.wake(stage)?.dynamic_config().number_of_listeners())
    }
}

/// Removes what dead dualgeo processes left behind (shared memory of crashed runs).
/// Returns how many dead nodes were cleaned.
pub fn clean_dead_nodes() -> usize {
    let mut cleaned = 0;
    let _ = Node::<Ipc>::list(&Config::default(), |state| {
        if let NodeState::Dead(view) = state {
            if view.try_remove_stale_resources().is_ok() {
                cleaned += 1;
            }
        }
        CallbackProgression::Continue
    });
    cleaned
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::DetectionMsg;
    use crate::service_names::new_run_id;

    #[test]
    fn frame_segment_size_follows_the_formula() {
        assert_eq!(FRAME_SEGMENT_SAMPLES, 3 * (2 + 2) + 2);
        assert_eq!(frame_segment_bytes(1000), 14 * (1000 + 48 + 200));
    }

    /// Every file under `dirs` (recursively), with its permission bits.
    fn files_with_modes(dirs: &[&str]) -> std::collections::BTreeMap<std::path::PathBuf, u32> {
        use std::os::unix::fs::PermissionsExt;
        let mut out = std::collections::BTreeMap::new();
        let mut stack: Vec<std::path::PathBuf> = dirs.iter().map(Into::into).collect();
        while let Some(dir) = stack.pop() {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            for entry in entries.flatten() {
                // Files of other tests may vanish between the listing and the stat.
                let Ok(meta) = entry.metadata() else {
                    continue;
                };
                if meta.is_dir() {
                    stack.push(entry.path());
                } else {
                    out.insert(entry.path(), meta.permissions().mode() & 0o777);
                }
            }
        }
        out
    }

    /// Issue #13, item 8: the shared memory and the files iceoryx2 creates for a run
    /// (segments in /dev/shm, service and node records under /tmp/iceoryx2) are the
    /// owner's only: no group or other bit. Another user on the ground station can
    /// neither read the frames nor inject a pose.
    #[test]
    fn shared_memory_and_service_files_are_owner_only() {
        let dirs = ["/dev/shm", "/tmp/iceoryx2"];
        let before = files_with_modes(&dirs);
        let run = new_run_id();
        let a = Endpoint::new(&run, "perm-a").unwrap();
        let _publisher = a.publisher::<DetectionMsg>(Topic::Detections).unwrap();
        let _subscriber = a.subscriber::<DetectionMsg>(Topic::Detections).unwrap();
        let _frames = a.frame_publisher(Uav::Left, 64 * 48 * 3).unwrap();
        let _notifier = a.notifier(Stage::Matching).unwrap();
        let _listener = a.listener(Stage::Matching).unwrap();
        let after = files_with_modes(&dirs);
        // One exception, measured and stated: iceoryx2 0.10's host-wide
        // `iox2_*_node.*.global_mgmt` (16 bytes, created once per host by the first
        // node of any user, then kept) is 0666. It is not per run and holds no frame or
        // pose; whether it is already there depends on what ran before, so it is
        // excluded rather than left to make this test order-dependent.
        let host_wide = |p: &std::path::Path| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.ends_with(".global_mgmt"))
        };
        let created: Vec<_> = after
            .iter()
            .filter(|(p, _)| !before.contains_key(*p) && !host_wide(p))
            .collect();
        assert!(!created.is_empty(), "no iceoryx2 file seen in {dirs:?}");
        let open: Vec<_> = created
            .iter()
            .filter(|(_, mode)| **mode & 0o077 != 0)
            .collect();
        assert!(open.is_empty(), "readable by others: {open:?}");
    }

    #[test]
    fn message_round_trip_with_a_wake_up() {
        let run = new_run_id();
        let a = Endpoint::new(&run, "test-a").unwrap();
        let b = Endpoint::new(&run, "test-b").unwrap();
        let listener = b.listener(Stage::Matching).unwrap();
        let sub = b.subscriber::<DetectionMsg>(Topic::Detections).unwrap();
        let publisher = a.publisher::<DetectionMsg>(Topic::Detections).unwrap();
        let notifier = a.notifier(Stage::Matching).unwrap();
        assert_eq!(
            a.subscriber_count::<DetectionMsg>(Topic::Detections)
                .unwrap(),
            1
        );
        assert_eq!(a.listener_count(Stage::Matching).unwrap(), 1);
        publisher
            .send_copy(DetectionMsg {
                seq: 42,
                found: 1,
                ..Default::default()
            })
            .unwrap();
        notifier.notify().unwrap();
        let mut woke = 0;
        listener
            .timed_wait(|_| woke += 1, std::time::Duration::from_secs(2))
            .unwrap();
        assert_eq!(woke, 1);
        let sample = sub.receive().unwrap().unwrap();
        assert_eq!(sample.payload().seq, 42);
    }
}
