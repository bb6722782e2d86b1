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

#[test]
fn free_bus_gets_only_a_stop() {
    let mut scl_e = vec![P::set(State::High)];
    scl_e.extend(stop_scl());
    let mut sda_e = vec![P::set(State::High), P::get(State::High)];
    sda_e.extend(stop_sda(true));
    let (mut scl, mut sda) = (Pin::new(&scl_e), Pin::new(&sda_e));
    let r = recover_bus(&mut scl, &mut sda, &mut NoopDelay, 5).unwrap();
    assert_eq!(
        r,
        Recovery {
            pulses: 0,
            sda_released: true
        }
    );
    scl.done();
    sda.done();
}

#[test]
fn slave_releases_after_three_pulses() {
    let mut scl_e = vec![P::set(State::High)];
    for _ in 0..3 {
        scl_e.extend(pulse());
    }
    scl_e.extend(stop_scl());
    let mut sda_e = vec![P::set(State::High)];
    sda_e.extend([
        P::get(State::Low),
        P::get(State::Low),
        P::get(State::Low),
        P::get(State::High),
    ]);
    sda_e.extend(stop_sda(true));
    let (mut scl, mut sda) = (Pin::new(&scl_e), Pin::new(&sda_e));
    let r = recover_bus(&mut scl, &mut sda, &mut NoopDelay, 5).unwrap();
    assert_eq!(
        r,
        Recovery {
            pulses: 3,
            sda_released: true
        }
    );
    scl.done();
    sda.done();
}

#[test]
fn stuck_forever_stops_after_nine_pulses() {
    let mut scl_e = vec![P::set(State::High)];
    for _ in 0..9 {
        scl_e.extend(pulse());
    }
    scl_e.extend(stop_scl());
    let mut sda_e = vec![P::set(State::High)];
    sda_e.extend((0..9).map(|_| P::get(State::Low)));
    sda_e.extend(stop_sda(false));
    let (mut scl, mut sda) = (Pin::new(&scl_e), Pin::new(&sda_e));
    let r = recover_bus(&mut scl, &mut sda, &mut NoopDelay, 5).unwrap();
    assert_eq!(
        r,
        Recovery {
            pulses: 9,
            sda_released: false
        }
    );
    scl.done();
    sda.done();
}
