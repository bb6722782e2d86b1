pub mod adev;
pub mod calibrate;
pub mod device;
pub mod export;
pub mod fit;
pub mod heading;
pub mod record;
pub mod simulate;
