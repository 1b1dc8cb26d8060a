//! The log written and read back.

use super::*;
use std::path::Path;
use std::sync::atomic::Ordering;
use std::time::Instant;
use vtol_link::dialect::{self, MavMessage};

fn heartbeat(seq: u8) -> Frame {
    Frame::encode_v2(
        vtol_link::SystemId(255),
        vtol_link::ComponentId(190),
        seq,
        &vtol_link::gcs_heartbeat(),
    )
}

#[test]
fn file_name_is_utc_date() {
    let t = UNIX_EPOCH + Duration::from_secs(1_795_346_880);
    assert_eq!(log_file_name(t), "2026-11-22_11-28-00.tlog");
}

#[test]
fn round_trip_with_direction_bits_and_signing_withheld() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.tlog");
    let mut w = TlogWriter::create(&path).unwrap();
    let t = 1_795_346_880_485_324;
    assert!(
        w.write(&Record {
            t_us: t,
            direction: Direction::FromVehicle,
            frame: heartbeat(1)
        })
        .unwrap()
    );
    assert!(
        w.write(&Record {
            t_us: t + 10,
            direction: Direction::ToVehicle,
            frame: heartbeat(2)
        })
        .unwrap()
    );
    let signing = MavMessage::SETUP_SIGNING(dialect::SETUP_SIGNING_DATA::default());
    assert!(
        !w.write(&Record {
            t_us: t,
            direction: Direction::ToVehicle,
            frame: Frame::encode_v2(
                vtol_link::SystemId(255),
                vtol_link::ComponentId(0),
                3,
                &signing
            )
        })
        .unwrap()
    );
    w.flush().unwrap();
    let recs: Vec<_> = TlogReader::open(&path).unwrap().collect();
    assert_eq!(recs.len(), 2);
    assert_eq!(recs[0].0, t & !3);
    assert_eq!(recs[1].0 & 3, 3);
    assert_eq!(recs[1].1.seq(), 2);
}

#[test]
fn torn_tail_and_garbage_are_survived() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("b.tlog");
    let mut w = TlogWriter::create(&path).unwrap();
    for seq in 0..3 {
        w.write(&Record {
            t_us: 8,
            direction: Direction::FromVehicle,
            frame: heartbeat(seq),
        })
        .unwrap();
    }
    w.flush().unwrap();
    let mut data = std::fs::read(&path).unwrap();
    let record_len = data.len() / 3;
    data.truncate(data.len() - 5);
    let mut r = TlogReader::from_bytes(data);
    assert_eq!(r.by_ref().count(), 2);
    assert_eq!(r.truncated_tail_bytes, record_len - 5);
    assert_eq!(r.skipped_bytes, 0);
}

fn records_with_garbage(garbage: &[Vec<u8>]) -> (Vec<u8>, Vec<Vec<u8>>) {
    let mut data = Vec::new();
    let mut frames = Vec::new();
    for (i, g) in garbage.iter().enumerate() {
        data.extend_from_slice(g);
        let f = Frame::encode_v2(
            vtol_link::SystemId(1),
            vtol_link::ComponentId(1),
            i as u8,
            &vtol_link::gcs_heartbeat(),
        );
        // Unix µs, as loggers stamp records (2026-11-22), 1 ms apart.
        data.extend_from_slice(&(1_795_346_880_000_000 + i as u64 * 1000).to_be_bytes());
        data.extend_from_slice(f.as_bytes());
        frames.push(f.as_bytes().to_vec());
    }
    (data, frames)
}

#[test]
fn garbage_that_looks_like_a_frame_of_an_unknown_id_is_skipped() {
    // A stamp, then a v2 header of message id 0xABCDEF (not in the dialect, so no CRC to
    // check) with a short length. With a time far from the log's it is garbage, between
    // records and in step; with a time that fits, in step and with a whole checked record
    // behind it, the same frame is a record.
    let header = [0xFD, 1, 0, 0, 9, 9, 9, 0xEF, 0xCD, 0xAB, 0, 0, 0];
    let mut far = vec![0xFFu8; 8];
    far.extend_from_slice(&header);
    let mut near = 1_795_346_880_003_500u64.to_be_bytes().to_vec();
    near.extend_from_slice(&header);
    let mut after_garbage = vec![0x55];
    after_garbage.extend_from_slice(&far);
    let (data, frames) = records_with_garbage(&[
        vec![],
        vec![0x55, 0x13],
        after_garbage,
        far.clone(),
        near.clone(),
        vec![],
    ]);
    let mut r = TlogReader::from_bytes(data);
    let got: Vec<Vec<u8>> = r.by_ref().map(|(_, f)| f.as_bytes().to_vec()).collect();
    let mut want = frames.clone();
    want.insert(4, near[8..].to_vec());
    assert_eq!(got, want);
    assert_eq!(r.skipped_bytes, 2 + 1 + 21 + 21);
    assert_eq!(r.truncated_tail_bytes, 0);
}

#[test]
fn a_whole_unchecked_frame_stamped_zero_at_the_start_is_garbage() {
    // Found by the property test below: garbage that forms a whole frame of an unknown id
    // (v1, id 52) right before the first record, stamped 0.
    let mut g = vec![0u8; 8];
    g.extend_from_slice(&[254, 12, 0, 0, 0, 52]);
    g.extend_from_slice(&[0; 14]);
    let (data, frames) = records_with_garbage(&[g]);
    let mut r = TlogReader::from_bytes(data);
    let got: Vec<Vec<u8>> = r.by_ref().map(|(_, f)| f.as_bytes().to_vec()).collect();
    assert_eq!(got, frames);
    assert_eq!(r.skipped_bytes, 28);
}

#[test]
fn an_unchecked_header_in_garbage_does_not_swallow_the_record_behind_it() {
    // Found by the property test below: a v2 header of an unknown id (no CRC) whose length
    // reaches over the next record. The record's own CRC-checked frame must win.
    let (data, frames) =
        records_with_garbage(&[vec![0, 0, 0, 0, 0, 0, 0, 0, 253, 52], vec![0; 33]]);
    let mut r = TlogReader::from_bytes(data);
    let got: Vec<Vec<u8>> = r.by_ref().map(|(_, f)| f.as_bytes().to_vec()).collect();
    assert_eq!(got, frames);
    assert_eq!(r.skipped_bytes, 10 + 33);
}

proptest::proptest! {
    #[test]
    fn every_record_survives_garbage_between_records(
        garbage in proptest::collection::vec(proptest::collection::vec(proptest::num::u8::ANY, 0..40), 1..30),
    ) {
        let (data, frames) = records_with_garbage(&garbage);
        let total: usize = garbage.iter().map(Vec::len).sum();
        let mut r = TlogReader::new(Box::new(std::io::Cursor::new(data)));
        let got: Vec<Vec<u8>> = r.by_ref().map(|(_, f)| f.as_bytes().to_vec()).collect();
        proptest::prop_assert_eq!(got, frames);
        proptest::prop_assert_eq!(r.skipped_bytes, total);
    }
}

#[test]
fn a_full_disk_is_counted_and_the_writer_keeps_taking_records() {
    let full = Path::new("/dev/full");
    if !full.exists() {
        return;
    }
    let h = TlogHandle::start_at(full, 16).unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    // Keep logging until the failed flush shows up in the counters.
    while h.stats.write_errors.load(Ordering::Acquire) == 0 {
        h.log(Record::now(Direction::FromVehicle, heartbeat(1)));
        assert!(Instant::now() < deadline, "write error never reported");
        std::thread::sleep(Duration::from_millis(5));
    }
    let why = h.stats.failing().expect("the failure is shown");
    assert!(why.contains("space"), "{why}");
    h.log(Record::now(Direction::FromVehicle, heartbeat(2)));
    h.close();
}

#[test]
fn an_existing_log_is_never_overwritten() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("kept.tlog");
    std::fs::write(&path, b"earlier flight").unwrap();
    let err = TlogWriter::create(&path).unwrap_err().to_string();
    assert!(err.contains("kept.tlog"), "{err}");
    assert_eq!(std::fs::read(&path).unwrap(), b"earlier flight");
}

#[test]
fn logs_started_in_the_same_second_get_their_own_files() {
    let dir = tempfile::tempdir().unwrap();
    let t = UNIX_EPOCH + Duration::from_secs(1_795_346_880);
    let (a, mut wa) = create_unique(dir.path(), t).unwrap();
    let (b, mut wb) = create_unique(dir.path(), t).unwrap();
    let (c, _) = create_unique(dir.path(), t).unwrap();
    assert_eq!(a.file_name().unwrap(), "2026-11-22_11-28-00.tlog");
    assert_eq!(b.file_name().unwrap(), "2026-11-22_11-28-00-2.tlog");
    assert_eq!(c.file_name().unwrap(), "2026-11-22_11-28-00-3.tlog");
    // Interleaved writes land in their own files, whole.
    for seq in 0..10 {
        for w in [&mut wa, &mut wb] {
            w.write(&Record {
                t_us: 8,
                direction: Direction::FromVehicle,
                frame: heartbeat(seq),
            })
            .unwrap();
        }
    }
    wa.flush().unwrap();
    wb.flush().unwrap();
    for p in [&a, &b] {
        let seqs: Vec<u8> = TlogReader::open(p).unwrap().map(|r| r.1.seq()).collect();
        assert_eq!(seqs, (0..10).collect::<Vec<_>>());
    }
}

#[test]
fn writer_thread_flushes_within_the_interval() {
    let dir = tempfile::tempdir().unwrap();
    let h = TlogHandle::start(dir.path(), 16).unwrap();
    h.log(Record::now(Direction::FromVehicle, heartbeat(7)));
    // Wait on the file's content (upper bound 5 s), not on a fixed sleep.
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let n = TlogReader::open(&h.path).unwrap().count();
        if n == 1 {
            break;
        }
        assert!(Instant::now() < deadline, "record never reached the file");
        std::thread::yield_now();
    }
    h.close();
}
