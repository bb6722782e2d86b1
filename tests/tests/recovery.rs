//! Bus recovery (UM10204 3.1.16) against mocked pins and a mocked delay.

use embedded_hal_mock::eh1::delay::NoopDelay;
use embedded_hal_mock::eh1::digital::{Mock as Pin, State, Transaction as P};
use imu_drivers::recovery::{recover_bus, Recovery};

fn pulse() -> [P; 2] {
    [P::set(State::Low), P::set(State::High)]
}

fn stop_scl() -> Vec<P> {
    vec![P::set(State::Low), P::set(State::High)]
}

fn stop_sda(released: bool) -> Vec<P> {
    vec![
        P::set(State::Low),
        P::set(State::High),
        P::get(if released { State::High } else { State::Low }),
    ]
}

/// SCL: released high, `pulses` clock pulses, then its half of the STOP.
fn scl_with_pulses(pulses: usize) -> Vec<P> {
    let mut scl_e = vec![P::set(State::High)];
    for _ in 0..pulses {
        scl_e.extend(pulse());
    }
    scl_e.extend(stop_scl());
    scl_e
}

/// Recovery on pins that expect exactly `scl_e` and `sda_e`.
fn recover(scl_e: &[P], sda_e: &[P]) -> Recovery {
    let (mut scl, mut sda) = (Pin::new(scl_e), Pin::new(sda_e));
    let r = recover_bus(&mut scl, &mut sda, &mut NoopDelay, 5).unwrap();
    scl.done();
    sda.done();
    r
}

#[test]
fn free_bus_gets_only_a_stop() {
    let mut sda_e = vec![P::set(State::High), P::get(State::High)];
    sda_e.extend(stop_sda(true));
    assert_eq!(
        recover(&scl_with_pulses(0), &sda_e),
        Recovery {
            pulses: 0,
            sda_released: true
        }
    );
}

#[test]
fn slave_releases_after_three_pulses() {
    let mut sda_e = vec![P::set(State::High)];
    sda_e.extend([
        P::get(State::Low),
        P::get(State::Low),
        P::get(State::Low),
        P::get(State::High),
    ]);
    sda_e.extend(stop_sda(true));
    assert_eq!(
        recover(&scl_with_pulses(3), &sda_e),
        Recovery {
            pulses: 3,
            sda_released: true
        }
    );
}

#[test]
fn stuck_forever_stops_after_nine_pulses() {
    let mut sda_e = vec![P::set(State::High)];
    sda_e.extend((0..9).map(|_| P::get(State::Low)));
    sda_e.extend(stop_sda(false));
    assert_eq!(
        recover(&scl_with_pulses(9), &sda_e),
        Recovery {
            pulses: 9,
            sda_released: false
        }
    );
}
