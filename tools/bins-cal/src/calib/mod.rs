//! The calibration algorithms behind `bins-cal calibrate` and `verify`; the commands parse
//! the arguments, call these and print.
//!
//! | module | owns |
//! |---|---|
//! | [`dynamics`] | thermal dynamics (lag, play, bias play) identified jointly with the static temperature model from recordings with ramps |
//! | [`free`] | calibration without a tilter: static intervals, the orientation-free fit to \|f\| = 1 g, labelled holds with their tilts |
//! | [`segments`] | dwells of labelled rig recordings: means, stationarity, grouping by temperature |
//! | [`tilter`] | the 12 constants per temperature from labelled dwells (T(10), least squares); the temperature model T(11)/T(12) |
//! | [`tempco`] | temperature coefficients T(11)/T(12) from the constants at several temperatures (`tempco`) |
//! | [`shaker`] | shake-table holds and the vibration-error fits (physics §8) |

pub mod dynamics;
pub mod free;
pub mod segments;
pub mod shaker;
pub mod tempco;
pub mod tilter;
