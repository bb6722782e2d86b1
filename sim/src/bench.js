// Cycle budget from stage markers: the firmware stores a stage id into the `#[no_mangle]`
// u32 static PICO_IMU_STAGE on entering each stage of a sample set; the harness attributes
// core.cycles (executed cycles only, sleep excluded) between consecutive stores to the stage.
export async function benchReport() {
  throw new Error('bench: not implemented yet');
}
