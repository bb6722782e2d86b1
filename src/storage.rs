//! Settings storage: the calibration blob (`imu_cal::device::encode_blob`) and the attitude
//! filter's host settings (`pico_imu_core::settings::encode_orientation`), each one key of a
//! sequential-storage map in the last 64 KiB of the 2 MiB flash (memory.x reserves it).
//! Read at boot; written only on the host's request, while sampling is paused (a flash
//! program/erase stalls execute-in-place, so the CPU would stall mid-measurement).
use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_rp::flash::{Blocking, Flash};
use embassy_rp::peripherals::FLASH;
use embassy_rp::Peri;
use pico_imu_core::requests::Record;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

/// Pico W flash size.
pub const FLASH_SIZE: usize = 2 * 1024 * 1024;
/// Start of the calibration area, offset from the flash base (memory.x: `CAL` at 0x101F0000).
pub const CAL_FLASH_OFFSET: u32 = 0x1F_0000;
/// End of the calibration area (end of flash).
pub const CAL_FLASH_END: u32 = FLASH_SIZE as u32;
/// Map key of each record.
fn key(record: Record) -> u8 {
    match record {
        Record::Calibration => 1,
        Record::Orientation => 2,
    }
}

/// Blocking flash behind the async NorFlash interface sequential-storage wants. Blocking reads
/// are plain XIP loads; erase/program stall execute-in-place either way. (embassy-rp's async
/// reads stream XIP through DMA, which the emulator does not model.)
type F = BlockingAsync<Flash<'static, FLASH, Blocking, FLASH_SIZE>>;

pub struct Store {
    map: MapStorage<u8, F, Cache<Uncached, Uncached, Uncached, u8>>,
    buf: [u8; 512],
}

impl Store {
    pub fn new(flash: Peri<'static, FLASH>) -> Self {
        let flash = BlockingAsync::new(Flash::new_blocking(flash));
        let map = MapStorage::new(
            flash,
            MapConfig::new(CAL_FLASH_OFFSET..CAL_FLASH_END),
            Cache::new_uncached(),
        );
        Self { map, buf: [0; 512] }
    }

    /// Copy the stored `record` into `out`; `Ok(None)` when nothing was stored, `Err` when the
    /// flash could not be read or the record is damaged beyond sequential-storage's repair.
    pub async fn load(&mut self, record: Record, out: &mut [u8]) -> Result<Option<usize>, ()> {
        match self
            .map
            .fetch_item::<&[u8]>(&mut self.buf, &key(record))
            .await
        {
            Ok(Some(b)) if b.len() <= out.len() => {
                out[..b.len()].copy_from_slice(b);
                Ok(Some(b.len()))
            }
            Ok(Some(_)) => Err(()),
            Ok(None) => Ok(None),
            Err(e) => {
                defmt::warn!("{} store unreadable: {}", record, defmt::Debug2Format(&e));
                Err(())
            }
        }
    }

    /// Store `blob` as `record` (replacing the previous one).
    pub async fn save(&mut self, record: Record, blob: &[u8]) -> Result<(), ()> {
        self.map
            .store_item(&mut self.buf, &key(record), &blob)
            .await
            .map_err(|e| {
                defmt::warn!("{} store write failed: {}", record, defmt::Debug2Format(&e));
            })
    }
}
