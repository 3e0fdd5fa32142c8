//! The frames protocol over real iceoryx2 shared memory, producer and consumer in this
//! process (each on its own node): the handshake, frames in order with their poses and
//! points (and their times, layout version 2; version 1 still read), the end-of-stream
//! marker, and a frame out of sequence or of an unknown layout refused.

use nalgebra::{Isometry3, Vector3};
use pssba_client::services::{self, create_node};
use pssba_client::{FrameConsumer, FrameError, FrameHeader, FrameProducer, PointXyz};
use std::time::Duration;

/// This test's iceoryx2 prefix; iceoryx2's 16-byte management file of the prefix is removed
/// when the guard drops.
struct Prefix(String);

impl Drop for Prefix {
    fn drop(&mut self) {
        if let Ok(entries) = std::fs::read_dir("/dev/shm") {
            for entry in entries.flatten() {
                if entry.file_name().to_string_lossy().starts_with(&self.0) {
                    let _ = std::fs::remove_file(entry.path());
                }
            }
        }
    }
}

fn prefix(test: &str) -> Prefix {
    Prefix(format!("pssba-test-{}-{test}-", std::process::id()))
}

fn pose(k: usize) -> Isometry3<f64> {
    Isometry3::new(
        Vector3::new(k as f64, 1.0, 2.0),
        Vector3::new(0.0, 0.1, 0.2 * k as f64),
    )
}

#[test]
fn frames_arrive_in_order_with_their_poses_then_the_end() -> Result<(), FrameError> {
    let prefix = prefix("order");
    let producer_node = create_node(&prefix.0, "producer")?;
    let consumer_node = create_node(&prefix.0, "consumer")?;
    let mut producer = FrameProducer::create(&producer_node, 100, Duration::from_secs(5))?;
    let consumer = FrameConsumer::connect(&consumer_node, 7, Duration::from_secs(5))?;
    producer.wait_for_consumers(&producer_node, &[7], Duration::from_secs(5))?;
    for k in 0..3 {
        let truth = pose(k + 10);
        let sequence = producer.send(
            k as f64 * 0.1,
            &pose(k),
            Some(&truth),
            10 * k,
            |i| PointXyz {
                xyz_m: [i as f32, k as f32, 0.5],
            },
            None,
        )?;
        assert_eq!(sequence, k as u64);
    }
    // Larger than the service holds: refused before anything is sent.
    assert!(
        producer
            .send(0.5, &pose(0), None, 101, |_| PointXyz::default(), None)
            .is_err()
    );
    producer.end_stream()?;
    let mut seen = Vec::new();
    consumer.receive(|frame| -> Result<(), FrameError> {
        let k = frame.sequence as usize;
        assert_eq!(frame.world_from_lidar, pose(k));
        assert_eq!(frame.ground_truth, Some(pose(k + 10)));
        assert_eq!(frame.points.len(), 10 * k);
        if let Some(last) = frame.points.last() {
            assert_eq!(last.xyz_m, [(10 * k - 1) as f32, k as f32, 0.5]);
        }
        seen.push(k);
        Ok(())
    })?;
    assert_eq!(seen, [0, 1, 2]);
    assert!(consumer.ended());
    assert_eq!(consumer.received(), 3);
    Ok(())
}

#[test]
fn a_frame_out_of_sequence_is_refused() -> Result<(), FrameError> {
    let prefix = prefix("gap");
    let producer_node = create_node(&prefix.0, "producer")?;
    let consumer_node = create_node(&prefix.0, "consumer")?;
    // A producer that does not follow the protocol: a raw publisher on the frames service.
    let service = services::frames_service(&producer_node)?;
    let publisher = services::publisher(&service, 10, Duration::from_secs(5))?;
    let consumer = FrameConsumer::connect(&consumer_node, 1, Duration::from_secs(5))?;
    let mut sample = publisher.loan_slice(0).expect("loan");
    *sample.user_header_mut() = FrameHeader {
        sequence: 5,
        world_from_lidar: pssba_client::IsometryMsg::from_isometry(&pose(0)),
        layout_version: pssba_client::FRAME_LAYOUT_VERSION,
        ..FrameHeader::default()
    };
    sample.send().expect("send");
    let err = consumer
        .receive(|_| -> Result<(), FrameError> { Ok(()) })
        .expect_err("sequence 5 where 0 was expected");
    assert!(err.to_string().contains("sequence 5"), "{err}");
    Ok(())
}

#[test]
fn a_frame_of_another_layout_version_is_refused() -> Result<(), FrameError> {
    let prefix = prefix("version");
    let producer_node = create_node(&prefix.0, "producer")?;
    let consumer_node = create_node(&prefix.0, "consumer")?;
    let service = services::frames_service(&producer_node)?;
    let publisher = services::publisher(&service, 10, Duration::from_secs(5))?;
    let consumer = FrameConsumer::connect(&consumer_node, 1, Duration::from_secs(5))?;
    let mut sample = publisher.loan_slice(0).expect("loan");
    *sample.user_header_mut() = FrameHeader {
        world_from_lidar: pssba_client::IsometryMsg::from_isometry(&pose(0)),
        layout_version: pssba_client::FRAME_LAYOUT_VERSION + 1,
        ..FrameHeader::default()
    };
    sample.send().expect("send");
    let err = consumer
        .receive(|_| -> Result<(), FrameError> { Ok(()) })
        .expect_err("another version");
    assert!(err.to_string().contains("layout version 3"), "{err}");
    Ok(())
}

#[test]
fn a_new_producer_in_a_vanished_ones_place_counts_as_the_old_one_gone() -> Result<(), FrameError> {
    let prefix = prefix("replaced");
    let consumer_node = create_node(&prefix.0, "consumer")?;
    let first_node = create_node(&prefix.0, "first")?;
    let first = FrameProducer::create(&first_node, 100, Duration::from_secs(5))?;
    let consumer = FrameConsumer::connect(&consumer_node, 3, Duration::from_secs(5))?;
    first.wait_for_consumers(&first_node, &[3], Duration::from_secs(5))?;
    assert!(!consumer.producer_gone(&consumer_node));
    // The first producer leaves without its end-of-stream marker and a second one takes its
    // place before the consumer looks: the second waits for a ready report, so the consumer
    // must see the first as gone to end its stream and rejoin.
    drop(first);
    drop(first_node);
    let second_node = create_node(&prefix.0, "second")?;
    let mut second = FrameProducer::create(&second_node, 100, Duration::from_secs(5))?;
    assert!(consumer.producer_gone(&consumer_node));
    consumer.end_without_marker();
    assert!(consumer.rejoin()?);
    assert!(!consumer.producer_gone(&consumer_node));
    second.wait_for_consumers(&second_node, &[3], Duration::from_secs(5))?;
    second.send(0.0, &pose(0), None, 4, |_| PointXyz::default(), None)?;
    let mut received = 0;
    consumer.receive(|_| -> Result<(), FrameError> {
        received += 1;
        Ok(())
    })?;
    assert_eq!(received, 1);
    Ok(())
}

/// Layout version 2: a frame as large as the service holds, sent with each point's time,
/// arrives with the same times; one sent without arrives without; too few times are refused
/// before anything is sent.
#[test]
fn point_times_travel_with_their_frames() -> Result<(), FrameError> {
    let prefix = prefix("times");
    let producer_node = create_node(&prefix.0, "producer")?;
    let consumer_node = create_node(&prefix.0, "consumer")?;
    let mut producer = FrameProducer::create(&producer_node, 100, Duration::from_secs(5))?;
    let consumer = FrameConsumer::connect(&consumer_node, 7, Duration::from_secs(5))?;
    producer.wait_for_consumers(&producer_node, &[7], Duration::from_secs(5))?;
    let times: Vec<f32> = (0..100).map(|i| i as f32 * 1e-3 - 0.02).collect();
    let point = |i: usize| PointXyz {
        xyz_m: [i as f32, 2.0, 3.0],
    };
    producer.send(0.0, &pose(0), None, 100, point, Some(&times))?;
    producer.send(0.1, &pose(1), None, 40, point, None)?;
    let refused = producer
        .send(0.2, &pose(2), None, 40, point, Some(&times[..39]))
        .expect_err("39 times for 40 points");
    assert!(
        refused.to_string().contains("40 points and 39 point times"),
        "{refused}"
    );
    producer.end_stream()?;
    let mut seen = Vec::new();
    consumer.receive(|frame| -> Result<(), FrameError> {
        seen.push((frame.points.len(), frame.point_times_s()));
        assert_eq!(
            frame.points.last().map(|p| p.xyz_m[0]),
            Some(frame.points.len() as f32 - 1.0)
        );
        Ok(())
    })?;
    assert_eq!(seen, [(100, Some(times)), (40, None)]);
    Ok(())
}

/// A producer still writing layout version 1 is read, its frames as taken at one instant.
#[test]
fn a_version_1_frame_is_still_read() -> Result<(), FrameError> {
    let prefix = prefix("v1");
    let producer_node = create_node(&prefix.0, "producer")?;
    let consumer_node = create_node(&prefix.0, "consumer")?;
    let service = services::frames_service(&producer_node)?;
    let publisher = services::publisher(&service, 10, Duration::from_secs(5))?;
    let consumer = FrameConsumer::connect(&consumer_node, 1, Duration::from_secs(5))?;
    let mut sample = publisher.loan_slice(3).expect("loan");
    *sample.user_header_mut() = FrameHeader {
        world_from_lidar: pssba_client::IsometryMsg::from_isometry(&pose(0)),
        layout_version: 1,
        ..FrameHeader::default()
    };
    sample.send().expect("send");
    let mut seen = Vec::new();
    consumer.receive(|frame| -> Result<(), FrameError> {
        seen.push((frame.sequence, frame.points.len(), frame.point_times_s()));
        Ok(())
    })?;
    assert_eq!(seen, [(0, 3, None)]);
    Ok(())
}
