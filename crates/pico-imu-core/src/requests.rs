//! Host requests: identity, status, calibration, streaming mode, intervals, tables, the
//! attitude filter's declination and expected field.
use imu_cal::device::{decode_blob, encode_blob, BlobError, Calibration, MAX_BLOB_LEN};
use imu_proto::{
    CalFault, CalProblem, CalSource, CalStatus, DeviceMsg, ErrorCode, HostFrame, Identity,
    MagReference, OrientationConfig, Reply, Request, Scales, Vec, IMU_RATE_HZ, MAG_RATE_HZ,
    MAX_CAL_BLOB, PROTOCOL_VERSION,
};

use crate::device::Device;
use crate::outbox::FrameSink;
use crate::settings::{
    decode_orientation, encode_orientation, orientation_in_range, OrientationSetting, RecordError,
};

/// Allan engine overlap factor and levels, as reported in [`Identity`]: the engine types'
/// own parameters.
pub const ALLAN_OVERLAP: u8 = allan::stream::DEVICE_PARAMS[0] as u8;
pub const ALLAN_LEVELS: u8 = allan::stream::DEVICE_PARAMS[1] as u8;
pub const ALLAN_LEVELS_MAG: u8 = allan::stream::MAG_PARAMS[1] as u8;
const _: () = assert!(allan::stream::MAG_PARAMS[0] == allan::stream::DEVICE_PARAMS[0]);

/// What a flash record holds: each is one key of the device's store (src/storage.rs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Record {
    /// The calibration blob (`imu_cal::device::encode_blob`).
    Calibration,
    /// The attitude filter's host settings ([`encode_orientation`]).
    Orientation,
}

/// A record to write to flash for request `id`: a calibration the host asked to persist, or the
/// attitude filter's settings the host changed. The firmware pauses sampling, writes it and
/// reports back through [`Device::persisted`].
#[derive(Debug, Clone)]
pub struct PersistRequest {
    pub id: u16,
    pub record: Record,
    pub blob: Vec<u8, MAX_CAL_BLOB>,
}

/// The wire's reason for a blob the device refuses.
pub fn cal_problem(e: BlobError) -> CalProblem {
    match e {
        BlobError::WrongVersion { found, .. } => CalProblem::Version(found),
        BlobError::OutOfRange { .. } => CalProblem::OutOfRange,
        BlobError::Implausible(r) => CalProblem::Implausible {
            key: r.key as u8,
            axis: r.axis,
            value: r.value as f32,
            lo: r.lo as f32,
            hi: r.hi as f32,
        },
        BlobError::NoRange { .. } => CalProblem::OtherRanges,
        BlobError::NotFitted => CalProblem::OtherPart,
        _ => CalProblem::Corrupt,
    }
}

/// Decode a blob and check it was fitted for the parts and ranges the device runs (`scales`:
/// the physical unit per LSB of each sensor; the parts: [`crate::config::PARTS`]).
pub fn decode_for(blob: &[u8], scales: &Scales) -> Result<Calibration, CalProblem> {
    let cal = decode_blob(blob).map_err(cal_problem)?;
    if let Some(f) = cal.fitted_for() {
        if (f.imu, f.mag) != crate::config::PARTS {
            return Err(CalProblem::OtherPart);
        }
    }
    let lsb = [1.0 / scales.accel, 1.0 / scales.gyro, 1.0 / scales.mag];
    if !cal.fits_ranges(lsb) {
        return Err(CalProblem::OtherRanges);
    }
    Ok(cal)
}

impl Device {
    fn use_cal(&mut self, cal: Calibration, source: CalSource) {
        self.pipeline.set_cal(cal);
        self.cal_status = CalStatus {
            source,
            fault: None,
        };
    }

    /// Use a blob read from flash at boot; a bad one is reported and identity kept.
    pub fn load_stored(&mut self, blob: Option<&[u8]>) {
        let scales = self.pipeline.scales;
        match blob.map(|b| decode_for(b, &scales)) {
            None => self.use_cal(Calibration::identity(), CalSource::Identity),
            Some(Ok(cal)) => self.use_cal(cal, CalSource::Flash),
            Some(Err(e)) => {
                self.use_cal(Calibration::identity(), CalSource::Identity);
                self.cal_status.fault = Some(CalFault::Rejected(e));
            }
        }
    }

    /// The flash could not be read at boot.
    pub fn flash_unreadable(&mut self) {
        self.cal_status = CalStatus {
            source: CalSource::Identity,
            fault: Some(CalFault::Flash),
        };
    }

    /// Who we are.
    pub fn identity(&self) -> Identity {
        Identity {
            protocol: PROTOCOL_VERSION,
            firmware: imu_proto::String::try_from(self.firmware).unwrap_or_default(),
            board: imu_proto::String::try_from("Raspberry Pi Pico W").unwrap_or_default(),
            imu_rate_hz: IMU_RATE_HZ as u16,
            mag_rate_hz: MAG_RATE_HZ as u16,
            allan_overlap: ALLAN_OVERLAP,
            allan_levels: ALLAN_LEVELS,
            allan_levels_mag: ALLAN_LEVELS_MAG,
        }
    }

    /// Handle one host request. Returns a [`PersistRequest`] when the calibration must be
    /// written to flash (the reply then comes from [`Device::persisted`]).
    pub fn handle(
        &mut self,
        frame: HostFrame,
        uptime_us: u64,
        cpu: u16,
        sink: &mut impl FrameSink,
    ) -> Option<PersistRequest> {
        let id = frame.id;
        let reply = match frame.req {
            Request::Identify => Reply::Identity(self.identity()),
            Request::GetStatus => Reply::Status(self.status(uptime_us, cpu)),
            Request::GetCalibration => {
                let mut buf = [0u8; MAX_BLOB_LEN];
                match encode_blob(&self.pipeline.cal, &mut buf) {
                    Ok(b) => Reply::Calibration {
                        blob: Vec::from_slice(b).unwrap_or_default(),
                        status: self.cal_status,
                    },
                    Err(e) => Reply::Error(ErrorCode::BadCalibration(cal_problem(e))),
                }
            }
            Request::SetCalibration { blob, persist } => {
                match decode_for(&blob, &self.pipeline.scales) {
                    Ok(cal) => {
                        self.use_cal(cal, CalSource::Host);
                        // New corrections change the engines' input: old sums would mix scales.
                        self.reset_allan();
                        if persist {
                            return Some(PersistRequest {
                                id,
                                record: Record::Calibration,
                                blob,
                            });
                        }
                        Reply::Ok
                    }
                    Err(e) => Reply::Error(ErrorCode::BadCalibration(e)),
                }
            }
            Request::ResetAllan => {
                self.reset_allan();
                Reply::Ok
            }
            Request::SetMode(m) => {
                self.flush(sink);
                self.pipeline.mode = m;
                Reply::Ok
            }
            Request::SetIntervals {
                status_ms,
                tables_ms,
            } => {
                self.status_ms = status_ms;
                self.tables_ms = tables_ms;
                Reply::Ok
            }
            Request::GetTables => Reply::Tables {
                snapshot: self.start_tables(uptime_us),
            },
            Request::SetOrientation {
                declination_cdeg,
                reference,
            } => {
                let setting = (declination_cdeg, reference);
                match self.set_orientation(setting) {
                    // A setting other than the one in flash is stored (the reply comes with
                    // the write's outcome); the same one again writes nothing.
                    Reply::Ok if setting != self.stored_orientation => {
                        let mut blob = Vec::new();
                        // Ten bytes at most, into room for a calibration blob.
                        let _ = blob.extend_from_slice(&encode_orientation(setting));
                        return Some(PersistRequest {
                            id,
                            record: Record::Orientation,
                            blob,
                        });
                    }
                    r => r,
                }
            }
            Request::GetOrientation => Reply::Orientation(self.orientation_config()),
        };
        self.send(&DeviceMsg::Reply { id, reply }, sink);
        None
    }

    /// Use the attitude filter settings read from flash at boot (`None`: none stored); a
    /// damaged or unusable record is reported and the defaults kept (no declination, a learnt
    /// reference).
    pub fn load_orientation(&mut self, record: Option<&[u8]>) -> Result<(), RecordError> {
        let setting = match record.map(decode_orientation) {
            None => return Ok(()),
            Some(Err(e)) => return Err(e),
            Some(Ok(s)) => s,
        };
        self.set_orientation(setting);
        self.stored_orientation = setting;
        Ok(())
    }

    /// The attitude filter's declination and expected field (in RAM here; a change is stored
    /// by the caller of [`Device::handle`]).
    fn set_orientation(&mut self, setting: OrientationSetting) -> Reply {
        if !orientation_in_range(setting) {
            return Reply::Error(ErrorCode::OutOfRange);
        }
        let (declination_cdeg, reference) = setting;
        let ahrs = &mut self.pipeline.ahrs;
        ahrs.set_declination(f32::from(declination_cdeg) * 0.01);
        let ut_per_count = self.pipeline.scales.mag;
        // `None` asks for a learnt reference: one learnt (or being learnt) stays.
        if reference.is_some() || !ahrs.reference_learnt() {
            ahrs.set_reference(reference.map(|r| {
                (
                    r.field_nt as f32 * 1e-3 / ut_per_count,
                    f32::from(r.dip_cdeg) * 0.01,
                )
            }));
        }
        Reply::Ok
    }

    /// The attitude filter's settings in use.
    pub fn orientation_config(&self) -> OrientationConfig {
        let ahrs = &self.pipeline.ahrs;
        let ut_per_count = self.pipeline.scales.mag;
        OrientationConfig {
            declination_cdeg: libm::roundf(ahrs.declination() * 100.0) as i16,
            reference: ahrs.reference().map(|(field, dip)| MagReference {
                field_nt: libm::roundf(field * ut_per_count * 1e3) as u32,
                dip_cdeg: libm::roundf(dip * 100.0) as i16,
            }),
            learnt: ahrs.reference_learnt(),
        }
    }

    /// Report the outcome of a [`PersistRequest`] (its settings are in use either way).
    pub fn persisted(&mut self, req: &PersistRequest, ok: bool, sink: &mut impl FrameSink) {
        let reply = match (req.record, ok) {
            (Record::Calibration, true) => {
                self.cal_status = CalStatus {
                    source: CalSource::Flash,
                    fault: None,
                };
                Reply::Ok
            }
            (Record::Calibration, false) => {
                self.cal_status.fault = Some(CalFault::Flash);
                Reply::Error(ErrorCode::FlashWrite)
            }
            (Record::Orientation, true) => {
                if let Ok(s) = decode_orientation(&req.blob) {
                    self.stored_orientation = s;
                }
                Reply::Ok
            }
            (Record::Orientation, false) => Reply::Error(ErrorCode::FlashWrite),
        };
        self.send(&DeviceMsg::Reply { id: req.id, reply }, sink);
    }

    /// Forget all Allan state. The round in progress describes the old state: abandoned.
    pub fn reset_allan(&mut self) {
        self.pipeline.reset_allan();
        self.tables.abandon();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::tests::settings;
    use crate::settings::DEFAULT_ORIENTATION;
    use imu_proto::FrameReader;

    use crate::test_util::Sink;

    impl Sink {
        /// The replies sent so far, emptied.
        fn replies(&mut self) -> std::vec::Vec<(u16, Reply)> {
            let mut rd = FrameReader::<4096>::new();
            let mut out = std::vec::Vec::new();
            rd.feed::<DeviceMsg>(&self.0, |m| {
                if let Ok(DeviceMsg::Reply { id, reply }) = m {
                    out.push((id, reply));
                }
            });
            self.0.clear();
            out
        }
    }

    fn device() -> Device {
        Device::new(crate::config::scales(), "test")
    }

    fn set(
        dev: &mut Device,
        sink: &mut Sink,
        id: u16,
        s: OrientationSetting,
    ) -> Option<PersistRequest> {
        let req = Request::SetOrientation {
            declination_cdeg: s.0,
            reference: s.1,
        };
        dev.handle(HostFrame { id, req }, 0, 0, sink)
    }

    /// A new setting asks for a flash write (the reply waits for it); a device booting with the
    /// written record uses the same settings; the same setting again writes nothing; a failed
    /// write is reported; a record that cannot be used leaves the defaults.
    #[test]
    fn orientation_settings_are_stored_and_survive_a_reboot() {
        let mut sink = Sink(std::vec::Vec::new());
        let mut dev = device();
        // The defaults need no record.
        assert!(set(&mut dev, &mut sink, 1, DEFAULT_ORIENTATION).is_none());
        assert_eq!(sink.replies(), [(1, Reply::Ok)]);
        for (k, s) in settings(50).into_iter().enumerate() {
            let id = 10 + k as u16;
            let req = set(&mut dev, &mut sink, id, s).expect("a changed setting is stored");
            assert_eq!(req.record, Record::Orientation);
            assert!(sink.replies().is_empty(), "the reply waits for the write");
            dev.persisted(&req, true, &mut sink);
            assert_eq!(sink.replies(), [(id, Reply::Ok)]);
            let before = dev.orientation_config();
            assert_eq!(before.declination_cdeg, s.0);
            // Reboot: a fresh device reading the record.
            let mut again = device();
            assert_eq!(again.load_orientation(Some(&req.blob)), Ok(()));
            let after = again.orientation_config();
            assert_eq!(after.declination_cdeg, s.0);
            assert_eq!(after.reference, before.reference);
            assert_eq!(after.reference.is_some(), s.1.is_some());
            // The same setting again: nothing to write.
            assert!(set(&mut again, &mut sink, id, s).is_none());
            assert_eq!(sink.replies(), [(id, Reply::Ok)]);
            assert!(set(&mut dev, &mut sink, id, s).is_none());
            assert_eq!(sink.replies(), [(id, Reply::Ok)]);
        }
        // A write that fails: the setting is in use, the host told.
        let req = set(&mut dev, &mut sink, 99, (-4_321, None)).expect("stored");
        dev.persisted(&req, false, &mut sink);
        assert_eq!(sink.replies(), [(99, Reply::Error(ErrorCode::FlashWrite))]);
        assert_eq!(dev.orientation_config().declination_cdeg, -4_321);
        // Nothing stored, or a damaged record: the defaults.
        let mut fresh = device();
        assert_eq!(fresh.load_orientation(None), Ok(()));
        assert_eq!(
            fresh.load_orientation(Some(&[1, 2])),
            Err(RecordError::Length(2))
        );
        let c = fresh.orientation_config();
        assert_eq!((c.declination_cdeg, c.reference), (0, None));
        // Out of range: refused, nothing to store.
        assert!(set(&mut fresh, &mut sink, 7, (20_000, None)).is_none());
        assert_eq!(sink.replies(), [(7, Reply::Error(ErrorCode::OutOfRange))]);
    }
}
