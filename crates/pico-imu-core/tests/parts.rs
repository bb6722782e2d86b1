//! A calibration fitted for the MPU-6050 is refused once the IMU identifies itself (WHO_AM_I)
//! as another part: the one in use is dropped with `Rejected(OtherPart)` in the status, and
//! uploads and stored blobs are refused from then on; on an MPU-6050, and with identity
//! corrections (fitted for no part), nothing changes.
use imu_cal::device::{
    encode_blob, Affine, Calibration, Fitted, GyroCorrection, ImuPart, MagPart, MAX_BLOB_LEN,
};
use imu_drivers::mpu6050::ChipId;
use imu_proto::{
    CalFault, CalProblem, CalSource, DeviceMsg, ErrorCode, FrameReader, HostFrame, Reply, Request,
};
use pico_imu_core::config;
use pico_imu_core::device::Device;
use pico_imu_core::msg::SensorMsg;
use pico_imu_core::outbox::FrameSink;

struct Sink(Vec<u8>);

impl FrameSink for Sink {
    fn room(&self) -> usize {
        usize::MAX
    }
    fn put(&mut self, frame: &[u8]) {
        self.0.extend_from_slice(frame);
    }
}

impl Sink {
    fn messages(&self) -> Vec<DeviceMsg> {
        let mut reader = FrameReader::<4096>::new();
        self.0
            .iter()
            .filter_map(|&b| reader.push::<DeviceMsg>(b))
            .map(|m| m.expect("a frame the device wrote decodes"))
            .collect()
    }
}

/// Every part the driver recognises by its WHO_AM_I.
const CHIPS: [ChipId; 10] = [
    ChipId::Mpu6050,
    ChipId::Mpu6500,
    ChipId::Mpu9250,
    ChipId::Mpu92xxVariant,
    ChipId::Mpu9255,
    ChipId::Mpu6515,
    ChipId::Icm20689,
    ChipId::Mpu6886,
    ChipId::Icm20602,
    ChipId::Icm20608,
];

/// Identity corrections recorded as fitted for the firmware's parts at its ranges.
fn fitted_blob() -> Vec<u8> {
    let s = config::scales();
    let fitted = Fitted::new(
        ImuPart::Mpu6050,
        MagPart::Qmc5883l,
        [1.0 / s.accel, 1.0 / s.gyro, 1.0 / s.mag],
    )
    .expect("the firmware's ranges");
    let cal = Calibration::fitted(
        Affine::IDENTITY,
        GyroCorrection::IDENTITY,
        Affine::IDENTITY,
        fitted,
    )
    .expect("identity is plausible");
    let mut buf = [0u8; MAX_BLOB_LEN];
    encode_blob(&cal, &mut buf).expect("encodes").to_vec()
}

fn device_with(blob: &[u8]) -> Device {
    let mut dev = Device::new(config::scales(), "test");
    dev.load_stored(Some(blob));
    assert_eq!(dev.cal_status().source, CalSource::Flash);
    assert_eq!(dev.cal_status().fault, None);
    dev
}

fn upload(dev: &mut Device, blob: &[u8]) -> (bool, Option<DeviceMsg>) {
    let mut sink = Sink(Vec::new());
    let req = Request::SetCalibration {
        blob: imu_proto::Vec::from_slice(blob).unwrap(),
        persist: true,
    };
    let persist = dev.handle(HostFrame { id: 7, req }, 0, 0, &mut sink);
    (persist.is_some(), sink.messages().pop())
}

#[test]
fn a_calibration_for_the_mpu6050_is_refused_on_another_part() {
    let blob = fitted_blob();
    for chip in CHIPS {
        let mut dev = device_with(&blob);
        let fitted = *dev.calibration();
        let mut sink = Sink(Vec::new());
        dev.on_sensor(&SensorMsg::ImuChip(chip), &mut sink);
        if chip == ChipId::Mpu6050 {
            assert_eq!(dev.cal_status().source, CalSource::Flash, "{chip:?}");
            assert_eq!(dev.cal_status().fault, None, "{chip:?}");
            assert_eq!(*dev.calibration(), fitted);
            assert_eq!(upload(&mut dev, &blob), (true, None), "{chip:?}");
            continue;
        }
        // The stored one is dropped, the reason in the status.
        assert_eq!(dev.cal_status().source, CalSource::Identity, "{chip:?}");
        assert_eq!(
            dev.cal_status().fault,
            Some(CalFault::Rejected(CalProblem::OtherPart)),
            "{chip:?}"
        );
        assert_eq!(*dev.calibration(), Calibration::identity(), "{chip:?}");
        // An upload is refused (nothing to persist), and so is the same blob from flash.
        assert_eq!(
            upload(&mut dev, &blob),
            (
                false,
                Some(DeviceMsg::Reply {
                    id: 7,
                    reply: Reply::Error(ErrorCode::BadCalibration(CalProblem::OtherPart)),
                })
            ),
            "{chip:?}"
        );
        dev.load_stored(Some(&blob));
        assert_eq!(dev.cal_status().source, CalSource::Identity, "{chip:?}");
        assert_eq!(
            dev.cal_status().fault,
            Some(CalFault::Rejected(CalProblem::OtherPart)),
            "{chip:?}"
        );
        // Identity corrections record no part: taken on any.
        let mut buf = [0u8; MAX_BLOB_LEN];
        let identity = encode_blob(&Calibration::identity(), &mut buf)
            .unwrap()
            .to_vec();
        assert_eq!(upload(&mut dev, &identity), (true, None), "{chip:?}");
        assert_eq!(dev.cal_status().source, CalSource::Host, "{chip:?}");
    }
}
