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

/// Allan engine overlap factor and levels, as reported in [`Identity`]: the engine types'
/// own parameters.
pub const ALLAN_OVERLAP: u8 = allan::stream::DEVICE_PARAMS[0] as u8;
pub const ALLAN_LEVELS: u8 = allan::stream::DEVICE_PARAMS[1] as u8;
pub const ALLAN_LEVELS_MAG: u8 = allan::stream::MAG_PARAMS[1] as u8;
const _: () = assert!(allan::stream::MAG_PARAMS[0] == allan::stream::DEVICE_PARAMS[0]);

/// A calibration the host asked to persist; the firmware pauses sampling, writes it and
/// reports back through [`Device::persisted`].
#[derive(Debug, Clone)]
pub struct PersistRequest {
    pub id: u16,
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
                            return Some(PersistRequest { id, blob });
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
            } => self.set_orientation(declination_cdeg, reference),
            Request::GetOrientation => Reply::Orientation(self.orientation_config()),
        };
        self.send(&DeviceMsg::Reply { id, reply }, sink);
        None
    }

    /// The attitude filter's declination and expected field (RAM only: lost at a reset).
    fn set_orientation(&mut self, declination_cdeg: i16, reference: Option<MagReference>) -> Reply {
        let ok_decl = (-18_000..=18_000).contains(&declination_cdeg);
        let ok_ref = reference.is_none_or(|r| {
            (1_000..=1_000_000).contains(&r.field_nt) && (-9_000..=9_000).contains(&r.dip_cdeg)
        });
        if !ok_decl || !ok_ref {
            return Reply::Error(ErrorCode::OutOfRange);
        }
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

    /// Report the outcome of a [`PersistRequest`].
    pub fn persisted(&mut self, id: u16, ok: bool, sink: &mut impl FrameSink) {
        let reply = if ok {
            self.cal_status = CalStatus {
                source: CalSource::Flash,
                fault: None,
            };
            Reply::Ok
        } else {
            self.cal_status.fault = Some(CalFault::Flash);
            Reply::Error(ErrorCode::FlashWrite)
        };
        self.send(&DeviceMsg::Reply { id, reply }, sink);
    }

    /// Forget all Allan state. The round in progress describes the old state: abandoned.
    pub fn reset_allan(&mut self) {
        self.pipeline.reset_allan();
        self.tables.abandon();
    }
}
