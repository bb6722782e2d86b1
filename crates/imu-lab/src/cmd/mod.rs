pub mod adev;
