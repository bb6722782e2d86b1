pub mod adev;
pub mod calibrate;
