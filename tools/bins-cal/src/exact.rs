//! Fixed-length arrays read from TOML with their exact length: `#[serde(deserialize_with =
//! "exact::array")]` and its kin refuse an array of any other length, so that
//! `u0_V = [0.001, a, b, c]` is an error naming the key instead of three values of four (serde
//! reads a `[T; N]` as the first N elements of a longer sequence and the TOML reader does not
//! check for more). Every fixed-length array of the calibration file, the scenario file and
//! `vibration --env` is read through here.

use serde::de::{Deserialize, Deserializer, Error};

/// Reads a sequence of exactly `N` elements.
struct Exact<T, const N: usize>([T; N]);

impl<'de, T: Deserialize<'de>, const N: usize> Deserialize<'de> for Exact<T, N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = Vec::<T>::deserialize(d)?;
        let n = v.len();
        <[T; N]>::try_from(v)
            .map(Exact)
            .map_err(|_| D::Error::invalid_length(n, &format!("an array of exactly {N} elements").as_str()))
    }
}

/// `[T; N]`, exactly N elements.
pub fn array<'de, D: Deserializer<'de>, T: Deserialize<'de>, const N: usize>(d: D) -> Result<[T; N], D::Error> {
    Exact::<T, N>::deserialize(d).map(|e| e.0)
}

/// `[[T; C]; R]`, exactly R rows of exactly C elements.
pub fn matrix<'de, D: Deserializer<'de>, T: Deserialize<'de>, const R: usize, const C: usize>(
    d: D,
) -> Result<[[T; C]; R], D::Error> {
    Exact::<Exact<T, C>, R>::deserialize(d).map(|e| e.0.map(|r| r.0))
}

/// `Option<[T; N]>` (with `#[serde(default)]` for a missing key).
pub fn option_array<'de, D: Deserializer<'de>, T: Deserialize<'de>, const N: usize>(
    d: D,
) -> Result<Option<[T; N]>, D::Error> {
    Option::<Exact<T, N>>::deserialize(d).map(|o| o.map(|e| e.0))
}

/// `Option<[[T; C]; R]>` (with `#[serde(default)]` for a missing key).
pub fn option_matrix<'de, D: Deserializer<'de>, T: Deserialize<'de>, const R: usize, const C: usize>(
    d: D,
) -> Result<Option<[[T; C]; R]>, D::Error> {
    Option::<Exact<Exact<T, C>, R>>::deserialize(d).map(|o| o.map(|e| e.0.map(|r| r.0)))
}

/// `[f64; N]` for a field of an internally tagged enum (a scenario step, a vibration, a
/// calibration's profile), where the reader's error loses the key: the message names `key`.
pub fn array_keyed<'de, D: Deserializer<'de>, const N: usize>(d: D, key: &str) -> Result<[f64; N], D::Error> {
    let v = Vec::<f64>::deserialize(d)?;
    let n = v.len();
    <[f64; N]>::try_from(v).map_err(|_| {
        D::Error::custom(format!("`{key}`: invalid length {n}, expected an array of exactly {N} elements"))
    })
}

/// [`array_keyed`] of an optional field (with `#[serde(default)]` for a missing key).
pub fn option_array_keyed<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
    key: &str,
) -> Result<Option<[f64; N]>, D::Error> {
    match Option::<Vec<f64>>::deserialize(d)? {
        None => Ok(None),
        Some(v) => {
            let n = v.len();
            <[f64; N]>::try_from(v).map(Some).map_err(|_| {
                D::Error::custom(format!("`{key}`: invalid length {n}, expected an array of exactly {N} elements"))
            })
        }
    }
}

/// Defines `fn NAME(d) -> [f64; N]` (or `Option<…>`) reading the field `KEY` through
/// [`array_keyed`] / [`option_array_keyed`], for `#[serde(deserialize_with = "NAME")]`.
#[macro_export]
macro_rules! keyed_array {
    ($name:ident, $key:literal, $n:literal) => {
        fn $name<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[f64; $n], D::Error> {
            $crate::exact::array_keyed(d, $key)
        }
    };
    ($name:ident, $key:literal, Option, $n:literal) => {
        fn $name<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<[f64; $n]>, D::Error> {
            $crate::exact::option_array_keyed(d, $key)
        }
    };
}
