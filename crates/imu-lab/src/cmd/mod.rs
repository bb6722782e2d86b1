pub mod adev;
pub mod calibrate;
pub mod device;
pub mod record;
