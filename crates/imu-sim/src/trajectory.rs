//! A board turned through a known trajectory: the true attitude at every instant and what an
//! MPU-6050 + QMC5883L on it read (gyro, accelerometer, magnetometer with hard and soft iron),
//! for the orientation tests (host unit tests of the device's AHRS, the emulator's streams).
//!
//! Frames: the world is NED (x magnetic north, y east, z down; the simulated world's north is
//! magnetic north, so the true heading here is the magnetic one); the body is forward-right-down.
//! The sensors' own axes are forward-left-up (the accelerometer reads +g on z lying level, as the
//! CSV contract's level board does), i.e. `(x, −y, −z)` of the body frame. The attitude is given
//! by aerospace Z-Y-X Euler angles (heading ψ, pitch θ, roll φ) interpolated linearly between
//! keyframes; the body rates are the exact kinematic rates of that path
//! (p = φ̇ − ψ̇ sin θ, q = θ̇ cos φ + ψ̇ sin φ cos θ, r = −θ̇ sin φ + ψ̇ cos φ cos θ).
use crate::Rng;

/// Standard gravity, m/s².
pub const G: f64 = 9.80665;

/// An attitude: roll, pitch, heading, degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Euler {
    pub roll: f64,
    pub pitch: f64,
    pub heading: f64,
}

impl Euler {
    pub const fn new(roll: f64, pitch: f64, heading: f64) -> Self {
        Euler {
            roll,
            pitch,
            heading,
        }
    }

    /// Body → world rotation matrix (rows: north, east, down components).
    pub fn matrix(&self) -> [[f64; 3]; 3] {
        let (sf, cf) = self.roll.to_radians().sin_cos();
        let (st, ct) = self.pitch.to_radians().sin_cos();
        let (sp, cp) = self.heading.to_radians().sin_cos();
        [
            [ct * cp, sf * st * cp - cf * sp, cf * st * cp + sf * sp],
            [ct * sp, sf * st * sp + cf * cp, cf * st * sp - sf * cp],
            [-st, sf * ct, cf * ct],
        ]
    }
}

/// Keyframes: the attitude at each time (s), linear in the Euler angles between them (headings
/// and rolls may run past ±180° for full turns), held after the last.
#[derive(Debug, Clone)]
pub struct Trajectory {
    pub keys: Vec<(f64, Euler)>,
}

impl Trajectory {
    /// The attitude and its Euler-angle rates (deg/s) at `t` s.
    pub fn at(&self, t: f64) -> (Euler, [f64; 3]) {
        let k = &self.keys;
        if t <= k[0].0 {
            return (k[0].1, [0.0; 3]);
        }
        for w in k.windows(2) {
            let ((t0, a), (t1, b)) = (w[0], w[1]);
            if t < t1 {
                let f = (t - t0) / (t1 - t0);
                let d = [b.roll - a.roll, b.pitch - a.pitch, b.heading - a.heading];
                let e = Euler::new(a.roll + f * d[0], a.pitch + f * d[1], a.heading + f * d[2]);
                return (e, d.map(|x| x / (t1 - t0)));
            }
        }
        (k[k.len() - 1].1, [0.0; 3])
    }

    /// Length, s.
    pub fn duration(&self) -> f64 {
        self.keys[self.keys.len() - 1].0
    }

    /// The emulator's orientation run, 32 s: still and level at 30° (3 s: convergence), a
    /// level turn of 360° at 45°/s, a roll to 60° and back and a pitch to 60° and back (30°/s),
    /// then a tumble through the sphere (eight legs of 1.5 s: roll and heading through 360° at
    /// 30°/s, pitch swinging ±40° at up to 53°/s), back level at 30°: it ends where it starts,
    /// so a stream repeating it is continuous.
    pub fn standard() -> Trajectory {
        let mut keys = vec![(0.0, Euler::new(0.0, 0.0, 30.0))];
        let mut t = 3.0;
        keys.push((t, Euler::new(0.0, 0.0, 30.0)));
        let mut push = |dt: f64, e: Euler| {
            t += dt;
            keys.push((t, e));
        };
        push(8.0, Euler::new(0.0, 0.0, 390.0)); // level turn, 45°/s
        push(2.0, Euler::new(60.0, 0.0, 390.0)); // roll to 60°
        push(2.0, Euler::new(0.0, 0.0, 390.0));
        push(2.0, Euler::new(0.0, 60.0, 390.0)); // pitch to 60°
        push(2.0, Euler::new(0.0, 0.0, 390.0));
        // The sphere: eight legs of 45° of roll and heading, pitch alternating ±40°.
        for j in 1..=8 {
            let pitch = match j {
                8 => 0.0,
                j if j % 2 == 1 => 40.0,
                _ => -40.0,
            };
            push(
                1.5,
                Euler::new(45.0 * j as f64, pitch, 390.0 + 45.0 * j as f64),
            );
        }
        push(1.0, Euler::new(360.0, 0.0, 750.0));
        Trajectory { keys }
    }

    /// The calibration wizard's run (`imu-lab serve`'s accelerometer poses and magnetometer
    /// turns), 80.5 s: level at 30° for 5 s, the standard run's turns and tumble (29 s), then
    /// seven more poses held 5 s each, turned between in 1–2 s — y up, z down, y down, x up,
    /// x down and two tilted (roll 45° pitch 30°, roll 135° pitch −35°) — and back level at
    /// 30°: every face of the accelerometer once, its start and end the same attitude.
    pub fn calibration() -> Trajectory {
        let level = Euler::new(0.0, 0.0, 30.0);
        let mut keys = vec![(0.0, level)];
        // the standard run after its first 3 s, 2 s later: its level start held 5 s
        keys.extend(
            Trajectory::standard().keys[1..]
                .iter()
                .map(|&(t, e)| (t + 2.0, e)),
        );
        let mut t = keys[keys.len() - 1].0;
        let mut pose = |turn: f64, roll: f64, pitch: f64, hold: f64| {
            let e = Euler::new(roll, pitch, 750.0);
            t += turn;
            keys.push((t, e));
            if hold > 0.0 {
                t += hold;
                keys.push((t, e));
            }
        };
        pose(1.0, 450.0, 0.0, 5.0); // y up
        pose(1.0, 540.0, 0.0, 5.0); // z down
        pose(1.0, 630.0, 0.0, 5.0); // y down
        pose(1.5, 720.0, 90.0, 5.0); // x up
        pose(2.0, 720.0, -90.0, 5.0); // x down
        pose(1.5, 765.0, 30.0, 5.0);
        pose(1.5, 855.0, -35.0, 5.0);
        pose(2.0, 1080.0, 0.0, 0.0); // level at 30° (750° ≡ 30°), where it starts
        Trajectory { keys }
    }

    /// Whether the board is still at `t` (no key moves it there).
    pub fn is_still(&self, t: f64) -> bool {
        self.at(t).1 == [0.0; 3]
    }
}

/// Body rates (p, q, r), deg/s, of the Euler path at `e` with Euler rates `d` (deg/s).
pub fn body_rates(e: &Euler, d: &[f64; 3]) -> [f64; 3] {
    let (sf, cf) = e.roll.to_radians().sin_cos();
    let (st, ct) = e.pitch.to_radians().sin_cos();
    [
        d[0] - d[2] * st,
        d[1] * cf + d[2] * sf * ct,
        -d[1] * sf + d[2] * cf * ct,
    ]
}

/// The part: its errors and the place's field.
#[derive(Debug, Clone)]
pub struct Part {
    /// Geomagnetic field strength, µT, and dip (inclination, positive down), degrees.
    pub field_ut: f64,
    pub dip_deg: f64,
    /// Hard iron, µT, sensor axes.
    pub hard_iron: [f64; 3],
    /// Soft iron: the reading is `soft · B + hard` (identity: none).
    pub soft_iron: [[f64; 3]; 3],
    /// Gyro bias, deg/s, sensor axes.
    pub gyro_bias: [f64; 3],
    /// The accelerometer's offset o (m/s²) and scale s per axis, in the terms of the
    /// calibration's correction `a_cal = s·(a − o)` (imu-cal's six-pose fit): the part reads
    /// `a = f/s + o` for a specific force `f`. None: o = 0, s = 1.
    pub accel_offset: [f64; 3],
    pub accel_scale: [f64; 3],
    /// White noise per sample: gyro deg/s, accelerometer m/s², magnetometer µT (standard
    /// deviations).
    pub noise: [f64; 3],
}

impl Part {
    /// A perfect part in a mid-latitude field (50 µT, dip 60°).
    pub fn ideal() -> Part {
        Part {
            field_ut: 50.0,
            dip_deg: 60.0,
            hard_iron: [0.0; 3],
            soft_iron: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            gyro_bias: [0.0; 3],
            accel_offset: [0.0; 3],
            accel_scale: [1.0; 3],
            noise: [0.0; 3],
        }
    }

    /// The part of the emulator's orientation run and the demo: hard iron of 25 µT (half the
    /// field), a mild soft iron, a gyro bias of ≈ 0.5 deg/s and the MPU-6050 / QMC5883L noise
    /// levels (0.05 deg/s, 0.04 m/s², 0.2 µT per sample).
    pub fn hard_iron() -> Part {
        Part {
            hard_iron: [18.0, -12.0, 12.0],
            soft_iron: [[1.05, 0.02, 0.0], [0.02, 0.97, 0.01], [0.0, 0.01, 1.0]],
            gyro_bias: [0.4, -0.3, 0.2],
            noise: [0.05, 0.04, 0.2],
            ..Part::ideal()
        }
    }

    /// The field in the world frame (NED), µT.
    pub fn field_ned(&self) -> [f64; 3] {
        let (s, c) = self.dip_deg.to_radians().sin_cos();
        [self.field_ut * c, 0.0, self.field_ut * s]
    }
}

/// One instant's readings in the sensor axes (forward-left-up) and contract units.
#[derive(Debug, Clone, Copy)]
pub struct Reading {
    pub accel: [f64; 3],
    pub gyro: [f64; 3],
    pub mag: [f64; 3],
}

/// `Rᵀ v`: a world vector in the body frame.
fn to_body(r: &[[f64; 3]; 3], v: &[f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|j| r[0][j] * v[0] + r[1][j] * v[1] + r[2][j] * v[2])
}

/// Body (forward-right-down) → sensor (forward-left-up).
fn flu(v: [f64; 3]) -> [f64; 3] {
    [v[0], -v[1], -v[2]]
}

/// What the part reads at `t` on `traj`; noise drawn from `rng` when the part has any.
pub fn reading(traj: &Trajectory, part: &Part, t: f64, rng: &mut Rng) -> Reading {
    let (e, d) = traj.at(t);
    let r = e.matrix();
    let w = flu(body_rates(&e, &d));
    let f = flu(to_body(&r, &[0.0, 0.0, -G]));
    let b = flu(to_body(&r, &part.field_ned()));
    let s = &part.soft_iron;
    let mut mag = [0, 1, 2].map(|i| s[i][0] * b[0] + s[i][1] * b[1] + s[i][2] * b[2]);
    for (m, h) in mag.iter_mut().zip(part.hard_iron) {
        *m += h;
    }
    let mut out = Reading {
        accel: [0, 1, 2].map(|i| f[i] / part.accel_scale[i] + part.accel_offset[i]),
        gyro: [0, 1, 2].map(|i| w[i] + part.gyro_bias[i]),
        mag,
    };
    if part.noise.iter().any(|&n| n > 0.0) {
        for (v, sd) in [
            (&mut out.gyro, part.noise[0]),
            (&mut out.accel, part.noise[1]),
            (&mut out.mag, part.noise[2]),
        ] {
            for x in v.iter_mut() {
                *x += sd * rng.normal();
            }
        }
    }
    out
}

/// The smallest signed difference `a − b` of two angles, degrees, in (−180, 180].
pub fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    if d > 180.0 {
        d - 360.0
    } else {
        d
    }
}

/// A stream in the CSV contract at `rate_hz` for `seconds` (the trajectory repeated), with
/// truth columns `roll_true, pitch_true, heading_true` (degrees; heading magnetic, in
/// [0, 360)), for the emulator's sensor models and `imu-lab heading`.
pub fn write_stream<W: std::io::Write>(
    mut w: W,
    traj: &Trajectory,
    part: &Part,
    rate_hz: f64,
    seconds: f64,
    seed: u64,
) -> std::io::Result<()> {
    let mut rng = Rng::new(seed);
    writeln!(
        w,
        "t,ax,ay,az,gx,gy,gz,mx,my,mz,temp,roll_true,pitch_true,heading_true"
    )?;
    let n = (seconds * rate_hz).round() as usize;
    let period = traj.duration();
    for i in 0..n {
        let t = i as f64 / rate_hz;
        let tt = t % period;
        let r = reading(traj, part, tt, &mut rng);
        let (e, _) = traj.at(tt);
        writeln!(
            w,
            "{t:.6},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.4},{:.4},{:.4},25,{:.4},{:.4},{:.4}",
            r.accel[0],
            r.accel[1],
            r.accel[2],
            r.gyro[0],
            r.gyro[1],
            r.gyro[2],
            r.mag[0],
            r.mag[1],
            r.mag[2],
            angle_diff(e.roll, 0.0),
            e.pitch,
            e.heading.rem_euclid(360.0),
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The gyro rates integrate to the truth's attitude change (a sign or frame error in the
    /// kinematic rates would not).
    #[test]
    fn rates_integrate_to_the_attitude() {
        let traj = Trajectory::standard();
        let part = Part::ideal();
        let mut rng = Rng::new(1);
        // Integrate R' = R [ω]× in the body frame at 10 kHz.
        let dt = 1e-4;
        let mut r = traj.at(0.0).0.matrix();
        let n = (traj.duration() / dt) as usize;
        for i in 0..n {
            let t = (i as f64 + 0.5) * dt;
            let g = reading(&traj, &part, t, &mut rng).gyro;
            let w = [g[0], -g[1], -g[2]].map(|x| x.to_radians() * dt);
            let k = [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]];
            let mut next = r;
            for a in 0..3 {
                for b in 0..3 {
                    next[a][b] += (0..3).map(|c| r[a][c] * k[c][b]).sum::<f64>();
                }
            }
            r = next;
        }
        let truth = traj.at(traj.duration()).0.matrix();
        for a in 0..3 {
            for b in 0..3 {
                assert!(
                    (r[a][b] - truth[a][b]).abs() < 2e-3,
                    "{a}{b}: {r:?} vs {truth:?}"
                );
            }
        }
    }

    /// The standard run ends at the attitude it starts from (a repeated stream is continuous).
    #[test]
    fn the_standard_run_ends_where_it_starts() {
        let traj = Trajectory::standard();
        let (a, b) = (traj.at(0.0).0.matrix(), traj.at(traj.duration()).0.matrix());
        for i in 0..3 {
            for j in 0..3 {
                assert!((a[i][j] - b[i][j]).abs() < 1e-12, "{a:?} {b:?}");
            }
        }
    }

    /// The calibration run ends where it starts; its holds are the eight poses, each 5 s,
    /// every face of the accelerometer once (gravity's reaction along ±x, ±y, ±z).
    #[test]
    fn the_calibration_run_holds_eight_poses_and_ends_where_it_starts() {
        let traj = Trajectory::calibration();
        assert!((traj.duration() - 80.5).abs() < 1e-9, "{}", traj.duration());
        let (a, b) = (traj.at(0.0).0.matrix(), traj.at(traj.duration()).0.matrix());
        for i in 0..3 {
            for j in 0..3 {
                assert!((a[i][j] - b[i][j]).abs() < 1e-12, "{a:?} {b:?}");
            }
        }
        // the still stretches (sampled every 0.1 s) and the face each holds; the standard run's
        // last second (still, level) is too short to be a pose
        let mut holds: Vec<(f64, f64, [f64; 3])> = Vec::new();
        let mut rng = Rng::new(1);
        for i in 0..(traj.duration() * 10.0) as usize {
            let t = i as f64 / 10.0 + 0.05;
            if !traj.is_still(t) {
                continue;
            }
            let f = reading(&traj, &Part::ideal(), t, &mut rng)
                .accel
                .map(|x| x / G);
            match holds.last_mut() {
                Some(h) if t - h.1 < 0.11 => h.1 = t,
                _ => holds.push((t, t, f)),
            }
        }
        holds.retain(|h| h.1 - h.0 > 2.0);
        assert_eq!(holds.len(), 8, "{holds:?}");
        for h in &holds {
            assert!(h.1 - h.0 > 4.8, "{h:?}");
        }
        let faces: Vec<String> = holds[..6]
            .iter()
            .map(|h| {
                let k = (0..3)
                    .max_by(|&i, &j| h.2[i].abs().total_cmp(&h.2[j].abs()))
                    .unwrap();
                assert!((h.2[k].abs() - 1.0).abs() < 1e-9, "{h:?}");
                format!(
                    "{}{}",
                    if h.2[k] > 0.0 { "+" } else { "-" },
                    ["x", "y", "z"][k]
                )
            })
            .collect();
        assert_eq!(faces, ["+z", "+y", "-z", "-y", "+x", "-x"]);
    }

    /// Level and still: gravity on +z, the field's horizontal part along +x when heading north.
    #[test]
    fn level_board_reads_gravity_up_and_north_forward() {
        let traj = Trajectory {
            keys: vec![
                (0.0, Euler::new(0.0, 0.0, 0.0)),
                (1.0, Euler::new(0.0, 0.0, 0.0)),
            ],
        };
        let r = reading(&traj, &Part::ideal(), 0.5, &mut Rng::new(1));
        assert!((r.accel[2] - G).abs() < 1e-12 && r.accel[0].abs() < 1e-12);
        assert!((r.mag[0] - 25.0).abs() < 1e-9 && r.mag[1].abs() < 1e-9);
        // Dip down: the field's vertical component points down, −z in the sensor's axes.
        assert!((r.mag[2] + 50.0 * 60f64.to_radians().sin()).abs() < 1e-9);
    }
}
