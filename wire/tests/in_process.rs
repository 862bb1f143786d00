//! Publisher and subscriber in one process (separate nodes): the behaviour of the typed ports.
//! Cross-process behaviour (feed, monitor, killed publishers) is tested in the root `tests/`.

use std::time::{Duration, Instant};

use handeye_wire::domain::remove_domain_files;
use handeye_wire::message::{MessageEvent, MessagePublisher, MessageSendError, MessageSubscriber, WaitUntil};
use handeye_wire::stereo::{
    Delivery, PublishError, StereoEvent, StereoFrame, StereoFormat, StereoPublisher, StereoPublisherOptions, StereoSubscriber,
};
use handeye_wire::*;

/// A unique domain whose files are removed when the test ends.
struct TestDomain(Domain);

impl TestDomain {
    fn new(stem: &str) -> Self {
        Self(Domain::unique(stem))
    }
}

impl Drop for TestDomain {
    fn drop(&mut self) {
        let _ = remove_domain_files(&self.0);
    }
}

fn pixel(frame: u64, camera: usize, x: usize, y: usize) -> u8 {
    (x + 3 * y + 7 * camera + 11 * frame as usize) as u8
}

fn fill_pattern(frame: u64, g: &StereoFormat) -> impl FnOnce(&mut [u8]) {
    let g = *g;
    move |buf: &mut [u8]| {
        let (w, h, s) = (g.width as usize, g.height as usize, g.stride as usize);
        for cam in 0..g.camera_count as usize {
            for y in 0..h {
                let row = &mut buf[(cam * h + y) * s..(cam * h + y) * s + s];
                for (x, p) in row.iter_mut().enumerate() {
                    *p = if x < w { pixel(frame, cam, x, y) } else { 0xEE };
                }
            }
        }
    }
}

fn expect_frame(sub: &mut StereoSubscriber) -> StereoFrame {
    let start = Instant::now();
    loop {
        match sub.wait(Duration::from_secs(2)).unwrap() {
            StereoEvent::Frame(f) => return f,
            StereoEvent::PublisherUp => {}
            StereoEvent::Timeout => panic!("no frame after {:?}; stats {:?}", start.elapsed(), sub.stats()),
            StereoEvent::PublisherGone => panic!("publisher gone while expecting a frame"),
            StereoEvent::Interrupted => panic!("interrupted"),
        }
    }
}

fn drain(sub: &mut StereoSubscriber) -> Vec<u64> {
    let mut ids = Vec::new();
    while let Some(f) = sub.try_receive() {
        ids.push(f.frame_id());
    }
    ids
}

#[test]
fn frames_arrive_intact_with_padded_stride() {
    let d = TestDomain::new("roundtrip");
    let pub_node = WireNode::create(&d.0, "pub").unwrap();
    let sub_node = WireNode::create(&d.0, "sub").unwrap();
    let geometry = StereoFormat { stride: 40, ..StereoFormat::gray8_pair(37, 9) };
    let mut sub = StereoSubscriber::create(&sub_node, 2).unwrap();
    let mut publisher = StereoPublisher::create(&pub_node, geometry, StereoPublisherOptions::default()).unwrap();
    for k in 0..5u64 {
        let id = publisher.publish(1000 + k, fill_pattern(k, &geometry)).unwrap();
        assert_eq!(id, k);
        let f = expect_frame(&mut sub);
        assert_eq!(f.frame_id(), k);
        assert_eq!(f.header().capture_time_ns, 1000 + k);
        assert!(f.header().publish_time_ns > 0 && f.latency_ns().is_some());
        assert_eq!(f.payload().len(), 40 * 9 * 2);
        for cam in 0..2 {
            for y in 0..9 {
                let row = f.row(cam, y).unwrap();
                assert_eq!(row.len(), 37);
                assert!(row.iter().enumerate().all(|(x, &p)| p == pixel(k, cam, x, y)), "frame {k} cam {cam} row {y}");
            }
        }
        assert!(f.camera(2).is_none() && f.row(0, 9).is_none());
    }
    let s = sub.stats();
    assert_eq!((s.received, s.rejected_total(), s.missed), (5, 0, 0));
}

#[test]
fn malformed_samples_are_rejected_by_reason_and_the_receiver_keeps_working() {
    let d = TestDomain::new("malformed");
    let pub_node = WireNode::create(&d.0, "pub").unwrap();
    let sub_node = WireNode::create(&d.0, "sub").unwrap();
    let geometry = StereoFormat::gray8_pair(16, 8);
    let len = 16 * 8 * 2;
    let mut sub = StereoSubscriber::create(&sub_node, 2).unwrap();
    let mut p = StereoPublisher::create_raw(&pub_node, geometry, 4096, StereoPublisherOptions::default()).unwrap();
    let good = |id: u64| StereoHeader { frame_id: id, ..geometry.header() };
    let bad: Vec<(StereoHeader, usize, &str)> = vec![
        (StereoHeader { version: WIRE_VERSION + 1, ..good(1) }, len, "version"),
        (good(2), len - 1, "payload_length"),
        (StereoHeader { width: 0, ..good(3) }, len, "zero_size"),
        (StereoHeader { pixel_format: 42, ..good(4) }, len, "pixel_format"),
        (StereoHeader { width: 100_000, height: 100_000, stride: 100_000, ..good(5) }, len, "too_large"),
        (StereoHeader { stride: 15, ..good(6) }, 15 * 8 * 2, "stride"),
    ];
    p.publish_raw(good(0), len, |b| b.fill(1)).unwrap();
    assert_eq!(expect_frame(&mut sub).frame_id(), 0);
    for (i, (h, l, key)) in bad.iter().enumerate() {
        p.publish_raw(*h, *l, |b| b.fill(2)).unwrap();
        // Each bad sample is skipped: nothing is handed out, its counter goes up by one.
        let before = sub.stats().rejected_total();
        assert!(sub.try_receive().is_none(), "bad sample {key} was handed out");
        assert_eq!(sub.stats().rejected_total(), before + 1, "{key}");
        let idx = handeye_wire::stereo::StereoReject::KEYS.iter().position(|k| k == key).unwrap();
        assert_eq!(sub.stats().rejected[idx], 1, "{key} after {} bad samples", i + 1);
    }
    // The receiver still works: a good frame after all of them arrives intact.
    p.publish_raw(good(10), len, |b| b.fill(9)).unwrap();
    let f = expect_frame(&mut sub);
    assert_eq!(f.frame_id(), 10);
    assert!(f.payload().iter().all(|&b| b == 9));
    drop(f);
    // A frame id that does not increase is rejected too.
    p.publish_raw(good(10), len, |b| b.fill(9)).unwrap();
    assert!(sub.try_receive().is_none());
    assert_eq!(sub.stats().rejected[6], 1);
    let s = sub.stats();
    assert_eq!((s.received, s.rejected_total()), (2, 7));
    // Ids 1..=9 were never delivered as valid frames: the gap counts as missed.
    assert_eq!(s.missed, 9);
}

#[test]
fn latest_delivery_keeps_the_newest_frame_for_a_lagging_subscriber() {
    let d = TestDomain::new("latest");
    let pub_node = WireNode::create(&d.0, "pub").unwrap();
    let sub_node = WireNode::create(&d.0, "sub").unwrap();
    let geometry = StereoFormat::gray8_pair(8, 4);
    let mut sub = StereoSubscriber::create(&sub_node, 1).unwrap();
    let mut p = StereoPublisher::create(&pub_node, geometry, StereoPublisherOptions::default()).unwrap();
    p.publish(0, fill_pattern(0, &geometry)).unwrap();
    assert_eq!(drain(&mut sub), vec![0]);
    // The subscriber lags by four frames; its queue of one keeps only the newest.
    for k in 1..5 {
        p.publish(0, fill_pattern(k, &geometry)).unwrap();
    }
    assert_eq!(drain(&mut sub), vec![4]);
    assert_eq!(sub.stats().missed, 3);
}

#[test]
fn lossless_delivery_waits_for_the_subscriber_instead_of_dropping() {
    let d = TestDomain::new("lossless");
    let pub_node = WireNode::create(&d.0, "pub").unwrap();
    let sub_node = WireNode::create(&d.0, "sub").unwrap();
    let geometry = StereoFormat::gray8_pair(8, 4);
    let mut sub = StereoSubscriber::create(&sub_node, 1).unwrap();
    let options = StereoPublisherOptions {
        delivery: Delivery::Lossless { in_flight: 1, timeout: Duration::from_millis(50) },
        ..Default::default()
    };
    let mut p = StereoPublisher::create(&pub_node, geometry, options).unwrap();
    assert_eq!(p.subscriber_count(), 1);
    p.publish(0, fill_pattern(0, &geometry)).unwrap();
    // Frame 0 is still queued: there is no slot for frame 1, and nothing is overwritten.
    assert!(matches!(p.publish(0, fill_pattern(1, &geometry)), Err(PublishError::NoCapacity { .. })));
    assert_eq!(p.next_frame_id(), 1, "a frame that was not sent must not use up an id");
    let f = sub.try_receive().expect("frame 0");
    assert_eq!(f.frame_id(), 0);
    // Still held by the subscriber: still no slot.
    assert!(matches!(p.publish(0, fill_pattern(1, &geometry)), Err(PublishError::NoCapacity { .. })));
    drop(f);
    for k in 1..6 {
        p.publish(0, fill_pattern(k, &geometry)).unwrap();
        assert_eq!(drain(&mut sub), vec![k]);
    }
    assert_eq!(sub.stats().missed, 0);
}

#[test]
fn a_subscriber_that_leaves_frees_the_lossless_publisher() {
    let d = TestDomain::new("leaves");
    let pub_node = WireNode::create(&d.0, "pub").unwrap();
    let sub_node = WireNode::create(&d.0, "sub").unwrap();
    let geometry = StereoFormat::gray8_pair(8, 4);
    let sub = StereoSubscriber::create(&sub_node, 1).unwrap();
    let options = StereoPublisherOptions {
        delivery: Delivery::Lossless { in_flight: 1, timeout: Duration::from_millis(500) },
        ..Default::default()
    };
    let mut p = StereoPublisher::create(&pub_node, geometry, options).unwrap();
    p.publish(0, |b| b.fill(0)).unwrap();
    drop(sub); // leaves with frame 0 still queued
    p.publish(0, |b| b.fill(0)).expect("the departed subscriber's slot must come back");
}

#[test]
fn publisher_up_and_gone_are_reported_on_clean_exit() {
    let d = TestDomain::new("updown");
    let pub_node = WireNode::create(&d.0, "pub").unwrap();
    let sub_node = WireNode::create(&d.0, "sub").unwrap();
    let mut sub = StereoSubscriber::create(&sub_node, 2).unwrap();
    assert!(matches!(sub.wait(Duration::from_millis(10)).unwrap(), StereoEvent::Timeout));
    assert_eq!(sub.publisher_alive(), Some(false));
    let p = StereoPublisher::create(&pub_node, StereoFormat::gray8_pair(8, 4), StereoPublisherOptions::default()).unwrap();
    assert!(matches!(sub.wait(Duration::from_secs(2)).unwrap(), StereoEvent::PublisherUp));
    drop(p);
    assert!(matches!(sub.wait(Duration::from_secs(2)).unwrap(), StereoEvent::PublisherGone));
    // A second publisher (restart) is picked up by the same subscriber.
    let geometry = StereoFormat::gray8_pair(8, 4);
    let mut p = StereoPublisher::create(&pub_node, geometry, StereoPublisherOptions::default()).unwrap();
    assert!(matches!(sub.wait(Duration::from_secs(2)).unwrap(), StereoEvent::PublisherUp));
    p.publish(0, fill_pattern(0, &geometry)).unwrap();
    assert_eq!(expect_frame(&mut sub).frame_id(), 0);
    let s = sub.stats();
    assert_eq!((s.publisher_up, s.publisher_gone), (2, 1));
}

#[test]
fn only_one_stereo_publisher_per_domain() {
    let d = TestDomain::new("onepub");
    let node = WireNode::create(&d.0, "pub").unwrap();
    let g = StereoFormat::gray8_pair(8, 4);
    let _a = StereoPublisher::create(&node, g, StereoPublisherOptions::default()).unwrap();
    let options = StereoPublisherOptions { create_timeout: Duration::from_millis(100), ..Default::default() };
    let err = StereoPublisher::create(&node, g, options).err().expect("second publisher must be refused");
    assert!(err.to_string().contains("another publisher"), "{err}");
}

#[test]
fn domains_are_isolated() {
    let a = TestDomain::new("iso-a");
    let b = TestDomain::new("iso-b");
    let na = WireNode::create(&a.0, "pub").unwrap();
    let nb = WireNode::create(&b.0, "sub").unwrap();
    let g = StereoFormat::gray8_pair(8, 4);
    let mut sub = StereoSubscriber::create(&nb, 2).unwrap();
    let mut p = StereoPublisher::create(&na, g, StereoPublisherOptions::default()).unwrap();
    assert_eq!(p.subscriber_count(), 0);
    p.publish(0, |b| b.fill(1)).unwrap();
    assert!(matches!(sub.wait(Duration::from_millis(150)).unwrap(), StereoEvent::Timeout));
    assert_eq!(sub.stats().received, 0);
}

#[test]
fn commands_flow_in_order_and_invalid_ones_are_refused_and_rejected() {
    let d = TestDomain::new("commands");
    let daemon = WireNode::create(&d.0, "daemon").unwrap();
    let sim = WireNode::create(&d.0, "sim").unwrap();
    let mut sub = MessageSubscriber::<RobotCommand>::create(&sim).unwrap();
    let mut p = MessagePublisher::<RobotCommand>::create(&daemon).unwrap();
    let cmd = |seq: u64, frame_id: u64| RobotCommand {
        version: WIRE_VERSION,
        kind: CommandKind::MoveBy as u32,
        seq,
        frame_id,
        target_m: [0.01, 0.0, 0.0],
        ..Default::default()
    };
    // The sender refuses a NaN target...
    let nan = RobotCommand { target_m: [f32::NAN, 0.0, 0.0], ..cmd(9, 9) };
    assert!(matches!(p.send(&nan), Err(MessageSendError::Invalid { .. })));
    // ...and a receiver rejects one sent anyway, and keeps going.
    p.send(&cmd(1, 40)).unwrap();
    p.send_unchecked(&nan).unwrap();
    p.send_unchecked(&RobotCommand { kind: 77, ..cmd(2, 41) }).unwrap();
    p.send(&RobotCommand { kind: CommandKind::Stop as u32, ..cmd(3, NO_FRAME) }).unwrap();
    p.send(&cmd(4, 41)).unwrap();
    // Lockstep: apply every command, stop at the one answering frame 41.
    let mut seen = Vec::new();
    let r = sub
        .wait_until(Duration::from_secs(2), |c| {
            seen.push(c.seq);
            c.frame_id == 41
        })
        .unwrap();
    assert!(matches!(r, WaitUntil::Matched(c) if c.seq == 4));
    assert_eq!(seen, vec![1, 3, 4]);
    let s = sub.stats();
    assert_eq!((s.received, s.rejected[1], s.rejected[2]), (3, 1, 1));
    // Nothing more: the wait times out.
    assert!(matches!(sub.wait_until(Duration::from_millis(30), |_| true).unwrap(), WaitUntil::Timeout));
}

#[test]
fn robot_state_history_reaches_a_late_subscriber_and_telemetry_flows() {
    let d = TestDomain::new("state");
    let robot = WireNode::create(&d.0, "robot").unwrap();
    let daemon = WireNode::create(&d.0, "daemon").unwrap();
    let mut states = MessagePublisher::<RobotState>::create(&robot).unwrap();
    let s = RobotState { version: WIRE_VERSION, seq: 7, gripper_width_m: 0.04, ..Default::default() };
    states.send(&s).unwrap();
    // Subscribing after the send: history 1 delivers the current state as soon as the
    // publisher next looks at its connections (every send does).
    let mut sub = MessageSubscriber::<RobotState>::create(&daemon).unwrap();
    states.update_connections();
    let got = loop {
        match sub.wait(Duration::from_secs(2)).unwrap() {
            MessageEvent::Message(m) => break m,
            MessageEvent::PublisherUp => {}
            other => panic!("{other:?}"),
        }
    };
    assert_eq!(got, s);

    let mut tel_pub = MessagePublisher::<Telemetry>::create(&daemon).unwrap();
    let mut tel_sub = MessageSubscriber::<Telemetry>::create(&robot).unwrap();
    let mut t = Telemetry { phase: Phase::Servo as u32, frame_id: 12, ..Telemetry::default() };
    t.set_reason("servoing");
    tel_pub.send(&t).unwrap();
    let got = loop {
        match tel_sub.wait(Duration::from_secs(2)).unwrap() {
            MessageEvent::Message(m) => break m,
            MessageEvent::PublisherUp => {}
            other => panic!("{other:?}"),
        }
    };
    assert_eq!((got.frame_id, got.reason_text()), (12, "servoing".to_owned()));
}

#[test]
fn flush_waits_until_the_subscriber_has_taken_every_frame() {
    // iceoryx2 discards frames still queued when their publisher goes away, so a finite feed
    // must flush before it exits.
    let d = TestDomain::new("flush");
    let pub_node = WireNode::create(&d.0, "pub").unwrap();
    let sub_node = WireNode::create(&d.0, "sub").unwrap();
    let geometry = StereoFormat::gray8_pair(8, 4);
    let mut sub = StereoSubscriber::create(&sub_node, 2).unwrap();
    let options = StereoPublisherOptions {
        delivery: Delivery::Lossless { in_flight: 2, timeout: Duration::from_millis(50) },
        ..Default::default()
    };
    let mut p = StereoPublisher::create(&pub_node, geometry, options).unwrap();
    p.publish(0, fill_pattern(0, &geometry)).unwrap();
    p.publish(0, fill_pattern(1, &geometry)).unwrap();
    assert!(!p.flush(Duration::from_millis(30)).unwrap(), "nothing was taken yet");
    assert_eq!(drain(&mut sub), vec![0, 1]);
    assert!(p.flush(Duration::from_millis(500)).unwrap());
    // Flushing gives the slots back: publishing goes on.
    p.publish(0, fill_pattern(2, &geometry)).unwrap();
    assert_eq!(drain(&mut sub), vec![2]);
}

#[test]
fn chosen_frame_ids_keep_their_gaps_and_must_increase() {
    // A replayed recording keeps its ids: the subscriber must count the same gaps.
    let d = TestDomain::new("chosen-ids");
    let pub_node = WireNode::create(&d.0, "pub").unwrap();
    let sub_node = WireNode::create(&d.0, "sub").unwrap();
    let geometry = StereoFormat::gray8_pair(8, 4);
    let mut sub = StereoSubscriber::create(&sub_node, 2).unwrap();
    let mut publisher = StereoPublisher::create(&pub_node, geometry, StereoPublisherOptions::default()).unwrap();
    for (id, capture_ns) in [(5u64, 100u64), (6, 133), (9, 233)] {
        assert_eq!(publisher.publish_with_id(id, capture_ns, fill_pattern(id, &geometry)).unwrap(), id);
        let f = expect_frame(&mut sub);
        assert_eq!((f.frame_id(), f.header().capture_time_ns), (id, capture_ns));
    }
    assert_eq!(sub.stats().missed, 2, "ids 7 and 8 were skipped");
    assert!(matches!(
        publisher.publish_with_id(9, 300, fill_pattern(9, &geometry)),
        Err(PublishError::FrameIdNotIncreasing { frame_id: 9, next: 10 })
    ));
    assert_eq!(publisher.next_frame_id(), 10);
    assert_eq!(publisher.publish(400, fill_pattern(10, &geometry)).unwrap(), 10);
}
