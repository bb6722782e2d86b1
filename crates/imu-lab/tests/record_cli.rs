//! `imu-lab record` end to end against a fake device on a TCP port (the same link code that
//! talks to the emulator and to a real Pico): the CSV contract, and Ctrl-C ending a recording
//! cleanly with every row received so far written.
#![cfg(unix)]

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use imu_proto::{
    DeviceMsg, FrameEncoder, FrameReader, HostFrame, ImuSample, MagSample, Reply, SampleBatch,
    Scales, Vec as HVec, MAX_FRAME,
};

const SCALES: Scales = Scales {
    accel: 0.001,
    gyro: 0.01,
    mag: 0.1,
    temp: 0.01,
    temp_offset: 20.0,
};

/// A device that answers every request with `Ok` and streams one batch of 10 IMU samples
/// (1 kHz) and 2 magnetometer samples (200 Hz) every 5 ms of wall time, gz = sample number.
fn fake_device(listener: TcpListener) {
    let (mut sock, _) = listener.accept().expect("accept");
    sock.set_read_timeout(Some(Duration::from_millis(5)))
        .expect("timeout");
    let mut enc = FrameEncoder::new();
    let mut reader: Box<FrameReader<MAX_FRAME>> = Box::new(FrameReader::new());
    let mut out = vec![0u8; MAX_FRAME];
    let mut send = |sock: &mut TcpStream, msg: &DeviceMsg| -> bool {
        let n = enc.encode(msg, &mut out).expect("encode");
        sock.write_all(&out[..n]).is_ok()
    };
    let mut seq = 0u32;
    let mut buf = [0u8; 256];
    loop {
        match sock.read(&mut buf) {
            Ok(0) => return,
            Ok(n) => {
                for &b in &buf[..n] {
                    if let Some(Ok(HostFrame { id, .. })) = reader.push::<HostFrame>(b) {
                        let reply = DeviceMsg::Reply {
                            id,
                            reply: Reply::Ok,
                        };
                        if !send(&mut sock, &reply) {
                            return;
                        }
                    }
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => return,
        }
        let mut b = SampleBatch {
            calibrated: true,
            scales: SCALES,
            imu: HVec::new(),
            mag: HVec::new(),
        };
        for i in 0..10 {
            let s = seq + i;
            if i % 5 == 0 {
                let _ = b.mag.push(MagSample {
                    seq: s / 5,
                    t_us: u64::from(s) * 1000,
                    mag: [100, 200, 300],
                });
            }
            let _ = b.imu.push(ImuSample {
                seq: s,
                t_us: u64::from(s) * 1000,
                accel: [0, 0, 9810],
                gyro: [0, 0, s as i32],
                temp: Some(500),
            });
        }
        seq += 10;
        if !send(&mut sock, &DeviceMsg::Samples(b)) {
            return;
        }
    }
}

#[test]
fn ctrl_c_ends_a_recording_cleanly_with_every_row_written() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = listener.local_addr().expect("addr").port();
    std::thread::spawn(move || fake_device(listener));
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("rec.csv");
    let child = Command::new(env!("CARGO_BIN_EXE_imu-lab"))
        .args(["record", "--port", &format!("tcp:127.0.0.1:{port}")])
        .arg("--out")
        .arg(&csv)
        .args(["--seconds", "100000"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn imu-lab");
    // Let it record for a while (the file grows past its first buffer flush), then Ctrl-C.
    let start = Instant::now();
    while std::fs::metadata(&csv).map(|m| m.len()).unwrap_or(0) < 64 * 1024 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no rows recorded"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill -INT");
    assert!(kill.success());
    let out = child.wait_with_output().expect("wait");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "exit {:?}: {stderr}", out.status);
    assert!(stderr.contains("stopped by Ctrl-C"), "{stderr}");

    let text = std::fs::read_to_string(&csv).expect("csv");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("t,ax,ay,az,gx,gy,gz,mx,my,mz,temp,gap_before,q0,q1,q2,q3,roll,pitch,heading,ahrs")
    );
    // This device sends no attitude estimates: those eight columns are empty.
    let rows: Vec<Vec<f64>> = lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 20, "{l}");
            assert!(f[12..].iter().all(|x| x.is_empty()), "{l}");
            f[..12].iter().map(|x| x.parse::<f64>().expect(l)).collect()
        })
        .collect();
    assert!(rows.len() > 1000, "{} rows", rows.len());
    assert!(rows.iter().all(|r| r.len() == 12), "every row complete");
    assert!(rows.iter().all(|r| r[11] == 0.0), "nothing lost");
    // The summary counts exactly the rows in the file: nothing received was lost.
    assert!(
        stdout.contains(&format!(": {} rows over", rows.len())),
        "{stdout}"
    );
    // Consecutive samples, gz = sample number × 0.01 deg/s, t in seconds.
    for w in rows.windows(2) {
        assert!((w[1][0] - w[0][0] - 0.001).abs() < 1e-9, "t step");
        // Values are written as f32 (shortest round-trip form).
        assert!((w[1][6] - w[0][6] - 0.01).abs() < 1e-4, "gz step {w:?}");
    }
}
