//! Per-pixel sensor calibration from bias, dark and flat-field stacks:
//! streaming statistics, fits, calibration files and report plots.
//!
//! Empty until the calibration stage lands.
