//! Round trips of every message kind through the frame encoder, reader and decoder.
use imu_proto::*;

/// One encoded frame (delimiter included) as a `Vec`.
fn encode_vec<T: serde::Serialize>(
    enc: &mut FrameEncoder,
    msg: &T,
) -> Result<std::vec::Vec<u8>, EncodeError> {
    let mut out = std::vec![0u8; MAX_FRAME];
    let n = enc.encode(msg, &mut out)?;
    out.truncate(n);
    Ok(out)
}

fn scales() -> Scales {
    Scales {
        accel: 9.806_65 / 16384.0,
        gyro: 1.0 / 131.0,
        mag: 100.0 / 12000.0,
        temp: 1.0 / 340.0,
        temp_offset: 36.53,
    }
}

fn status() -> Status {
    Status {
        uptime_us: 123_456_789_012,
        samples_taken: 60_000,
        samples_dropped: 3,
        mag_samples: 12_000,
        mag_dropped: 4,
        fifo_overflows: 1,
        i2c_errors: 7,
        bus_faults: 1,
        bus_recoveries: 2,
        frames_rejected: 4,
        frames_unsent: 0,
        cpu_load_permille: 37,
        temp_milli_c: Some(-12_345),
        imu: SensorState::Ok,
        mag: SensorState::Stalled,
        imu_period_ns: 1_013_171,
        mag_period_ns: 0,
        cal: CalStatus {
            source: CalSource::Identity,
            fault: Some(CalFault::Rejected(CalProblem::Version(0))),
        },
        mode: StreamMode::Calibrated,
    }
}

fn table() -> AllanTable {
    let mut levels = Vec::new();
    for k in 0..MAX_LEVELS as u32 {
        levels
            .push(AllanLevel {
                m: 1 << k,
                stride: if k < 3 { 1 } else { 1 << (k - 3) },
                n2: 60_000 - (2u64 << k).min(59_999),
                // Values beyond u64 to exercise the u128 varint path.
                sum2: (u128::from(u64::MAX) << 20) + u128::from(k),
                n3: 59_000,
                sum3: u128::MAX - u128::from(k),
            })
            .unwrap();
    }
    AllanTable {
        channel: Channel::Gz,
        snapshot: u32::MAX,
        t_us: u64::MAX,
        tau0_ns: 1_013_171,
        scale: 1.0 / 131.0,
        pushed: 60_000,
        gaps: 1,
        levels,
    }
}

fn batch() -> SampleBatch {
    let mut imu = Vec::new();
    for i in 0..MAX_BATCH_IMU as u32 {
        imu.push(ImuSample {
            seq: u32::MAX - MAX_BATCH_IMU as u32 + i,
            t_us: 1_000 * u64::from(i) + u64::MAX / 2,
            accel: [i32::MIN, -1, i32::MAX],
            gyro: [0, 131 * i as i32, -32768],
            temp: if i % 2 == 0 { Some(-521) } else { None },
        })
        .unwrap();
    }
    let mut mag = Vec::new();
    for i in 0..MAX_BATCH_MAG as u32 {
        mag.push(MagSample {
            seq: i,
            t_us: 5_000 * u64::from(i),
            mag: [1200, -3400, 5600],
        })
        .unwrap();
    }
    SampleBatch {
        calibrated: true,
        scales: scales(),
        imu,
        mag,
    }
}

fn all_device_msgs() -> std::vec::Vec<DeviceMsg> {
    let mut blob = Vec::new();
    blob.extend_from_slice(&[0u8, 1, 2, 0, 0, 255, 0]).unwrap();
    std::vec![
        DeviceMsg::Samples(batch()),
        DeviceMsg::Table(table()),
        DeviceMsg::Status(status()),
        DeviceMsg::Event(Event::SensorBack {
            sensor: Sensor::Mag,
            t_us: 5,
            down_us: 2_000_000
        }),
        DeviceMsg::Event(Event::SensorStalled {
            sensor: Sensor::Imu,
            t_us: 99,
            since_us: 12
        }),
        DeviceMsg::Event(Event::BusFault {
            t_us: 1,
            fault: BusFault::Timeout
        }),
        DeviceMsg::Event(Event::BusRecovered {
            t_us: 2,
            pulses: 9,
            sda_released: true
        }),
        DeviceMsg::Event(Event::Gap {
            sensor: Sensor::Mag,
            at: 123_456_789_012,
            cause: GapCause::Overwritten,
            lost: u32::MAX,
            t_us: 77
        }),
        DeviceMsg::Reply {
            id: 11,
            reply: Reply::Tables { snapshot: 3 }
        },
        DeviceMsg::Reply {
            id: 7,
            reply: Reply::Ok
        },
        DeviceMsg::Reply {
            id: 8,
            reply: Reply::Status(status())
        },
        DeviceMsg::Reply {
            id: 9,
            reply: Reply::Error(ErrorCode::BadCalibration(CalProblem::Implausible {
                key: 3,
                axis: Some(0),
                value: 1.9,
                lo: 0.91,
                hi: 1.09
            }))
        },
        DeviceMsg::Reply {
            id: 10,
            reply: Reply::Calibration {
                blob,
                status: CalStatus {
                    source: CalSource::Host,
                    fault: None
                }
            },
        },
        DeviceMsg::Reply {
            id: u16::MAX,
            reply: Reply::Identity(Identity {
                protocol: PROTOCOL_VERSION,
                firmware: String::try_from("pico-imu 0.1.0").unwrap(),
                board: String::try_from("Pico W").unwrap(),
                imu_rate_hz: 1000,
                mag_rate_hz: 200,
                allan_overlap: 8,
                allan_levels: 24,
                allan_levels_mag: 22,
            }),
        },
        DeviceMsg::Orientation(
            [
                AhrsState::Converging,
                AhrsState::Tracking,
                AhrsState::MagField,
                AhrsState::MagDip,
            ]
            .iter()
            .enumerate()
            .map(|(i, &state)| Orientation {
                seq: u32::MAX - i as u32,
                t_us: u64::MAX - 7 * i as u64,
                q: [0.5, -0.5, 0.5, f32::MIN_POSITIVE],
                roll_deg: -179.99,
                pitch_deg: 90.0,
                heading_deg: 359.99,
                state,
            })
            .collect(),
        ),
        DeviceMsg::Reply {
            id: 11,
            reply: Reply::Orientation(OrientationConfig {
                declination_cdeg: -18_000,
                reference: Some(MagReference {
                    field_nt: 1_000_000,
                    dip_cdeg: i16::MIN,
                }),
                learnt: true,
            }),
        },
        DeviceMsg::Reply {
            id: 12,
            reply: Reply::Error(ErrorCode::OutOfRange),
        },
    ]
}

fn all_host_msgs() -> std::vec::Vec<HostFrame> {
    let mut blob = Vec::new();
    blob.extend_from_slice(&[0u8; MAX_CAL_BLOB]).unwrap();
    [
        Request::Identify,
        Request::GetStatus,
        Request::GetCalibration,
        Request::SetCalibration {
            blob,
            persist: true,
        },
        Request::ResetAllan,
        Request::SetMode(StreamMode::Raw),
        Request::SetIntervals {
            status_ms: 1000,
            tables_ms: 0,
        },
        Request::GetTables,
        Request::SetOrientation {
            declination_cdeg: 1234,
            reference: Some(MagReference {
                field_nt: 48_000,
                dip_cdeg: -6_000,
            }),
        },
        Request::SetOrientation {
            declination_cdeg: i16::MIN,
            reference: None,
        },
        Request::GetOrientation,
    ]
    .into_iter()
    .enumerate()
    .map(|(i, req)| HostFrame { id: i as u16, req })
    .collect()
}

#[test]
fn every_device_message_round_trips_through_one_stream() {
    let msgs = all_device_msgs();
    let mut enc = FrameEncoder::new();
    let mut wire = std::vec::Vec::new();
    for m in &msgs {
        let f = encode_vec(&mut enc, m).unwrap();
        // Exactly one delimiter, at the end: COBS removed every other zero.
        assert_eq!(f.iter().filter(|&&b| b == 0).count(), 1);
        assert_eq!(*f.last().unwrap(), 0);
        assert!(
            f.len() <= MAX_FRAME,
            "frame of {} bytes exceeds MAX_FRAME",
            f.len()
        );
        wire.extend_from_slice(&f);
    }
    let mut rd = FrameReader::<MAX_FRAME>::new();
    let mut got = std::vec::Vec::new();
    // Feed in awkward chunks (7 bytes) to exercise frames split across reads.
    for chunk in wire.chunks(7) {
        rd.feed::<DeviceMsg>(chunk, |r| got.push(r.unwrap()));
    }
    assert_eq!(got, msgs);
    assert_eq!(rd.stats().ok, msgs.len() as u32);
    assert_eq!(rd.stats().rejected(), 0);
}

#[test]
fn every_host_message_round_trips() {
    let mut enc = FrameEncoder::new();
    for m in all_host_msgs() {
        let mut f = encode_vec(&mut enc, &m).unwrap();
        f.pop();
        assert_eq!(decode::<HostFrame>(&mut f).unwrap(), m);
    }
}

#[test]
fn the_largest_messages_fit_the_frame_limit() {
    // A full table with worst-case u128 sums is the largest message; it must fit with margin.
    let mut enc = FrameEncoder::new();
    let f = encode_vec(&mut enc, &DeviceMsg::Table(table())).unwrap();
    assert!(
        f.len() < MAX_FRAME,
        "table frame {} B, limit {MAX_FRAME} B",
        f.len()
    );
    let f = encode_vec(&mut enc, &DeviceMsg::Samples(batch())).unwrap();
    assert!(f.len() < MAX_FRAME);
}

#[test]
fn a_flipped_bit_is_caught_by_the_crc() {
    let mut enc = FrameEncoder::new();
    let good = encode_vec(&mut enc, &DeviceMsg::Status(status())).unwrap();
    let mut bad = good.clone();
    // Flip one bit of a payload byte that is not a COBS code byte (byte 5 is data here) and
    // keep it non-zero so the frame boundary is intact.
    bad[5] ^= if bad[5] == 0x01 { 0x02 } else { 0x01 };
    let mut rd = FrameReader::<MAX_FRAME>::new();
    let mut out = std::vec::Vec::new();
    rd.feed::<DeviceMsg>(&bad, |r| out.push(r));
    rd.feed::<DeviceMsg>(&good, |r| out.push(r));
    assert_eq!(out.len(), 2);
    assert!(
        matches!(
            out[0],
            Err(DecodeError::Crc { .. }) | Err(DecodeError::Cobs)
        ),
        "{:?}",
        out[0]
    );
    assert_eq!(out[1].as_ref().unwrap(), &DeviceMsg::Status(status()));
    assert_eq!(rd.stats().rejected(), 1);
    assert_eq!(rd.stats().ok, 1);
}

#[test]
fn another_version_is_rejected_not_guessed() {
    // Hand-build a frame with the next version and a valid CRC.
    let other = PROTOCOL_VERSION + 1;
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    let mut payload = std::vec![other];
    payload.extend_from_slice(
        &postcard::to_allocvec(&HostFrame {
            id: 1,
            req: Request::Identify,
        })
        .unwrap(),
    );
    let c = crc.checksum(&payload);
    payload.extend_from_slice(&c.to_le_bytes());
    let mut f = std::vec![0u8; cobs::max_encoding_length(payload.len())];
    let n = cobs::encode(&payload, &mut f);
    f.truncate(n);
    assert_eq!(
        decode::<HostFrame>(&mut f),
        Err(DecodeError::Version(other))
    );
}

#[test]
fn a_valid_crc_around_an_unknown_variant_is_unknown() {
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    // id = 1, request discriminant 200 (no such request).
    let mut payload = std::vec![PROTOCOL_VERSION, 1, 200, 1];
    let c = crc.checksum(&payload);
    payload.extend_from_slice(&c.to_le_bytes());
    let mut f = std::vec![0u8; cobs::max_encoding_length(payload.len())];
    let n = cobs::encode(&payload, &mut f);
    f.truncate(n);
    assert_eq!(decode::<HostFrame>(&mut f), Err(DecodeError::Unknown));
}

#[test]
fn an_oversized_frame_is_dropped_and_the_next_one_is_read() {
    let mut rd = FrameReader::<64>::new();
    let mut out = std::vec::Vec::new();
    rd.feed::<HostFrame>(&[0x55; 200], |r| out.push(r));
    assert!(out.is_empty());
    rd.feed::<HostFrame>(&[0], |r| out.push(r));
    let mut enc = FrameEncoder::new();
    let f = encode_vec(
        &mut enc,
        &HostFrame {
            id: 3,
            req: Request::GetStatus,
        },
    )
    .unwrap();
    rd.feed::<HostFrame>(&f, |r| out.push(r));
    assert_eq!(out[0], Err(DecodeError::Oversize));
    assert_eq!(
        out[1],
        Ok(HostFrame {
            id: 3,
            req: Request::GetStatus
        })
    );
    assert_eq!(rd.stats().oversize, 1);
}

#[test]
fn scales_convert_to_contract_units() {
    let s = scales();
    // 16384 LSB = 1 g = 9.80665 m/s² at ±2 g; 131 LSB = 1 deg/s at ±250 deg/s.
    assert!((16384.0 * s.of(Channel::Az) - 9.806_65).abs() < 1e-5);
    assert!((131.0 * s.of(Channel::Gx) - 1.0).abs() < 1e-6);
    assert_eq!(
        Channel::ALL.map(|c| c.name()).join(","),
        "ax,ay,az,gx,gy,gz,mx,my,mz,temp"
    );
    assert_eq!(Channel::Mz.unit(), "µT");
}
