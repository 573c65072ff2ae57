//! Enums in this crate's JSON files (a run's `config.json`, the weights manifest) by the one
//! name their `name()` and `FromStr` share (`"partial"`, `"bf16"`, `"var1"`): fields say
//! `#[serde(with = "crate::by_name")]`.

use std::fmt::Display;
use std::str::FromStr;

use serde::{de::Error, Deserialize, Deserializer, Serializer};

/// An enum with one spelling per value, read back by [`FromStr`].
pub(crate) trait Named: FromStr + Copy {
    fn name(self) -> &'static str;
}

impl Named for rgm_data::Setting {
    fn name(self) -> &'static str {
        rgm_data::Setting::name(self)
    }
}

impl Named for rgm_nn::Precision {
    fn name(self) -> &'static str {
        rgm_nn::Precision::name(self)
    }
}

impl Named for crate::weights::Variant {
    fn name(self) -> &'static str {
        crate::weights::Variant::name(self)
    }
}

pub(crate) fn serialize<T: Named, S: Serializer>(value: &T, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(value.name())
}

pub(crate) fn deserialize<'de, T, D>(d: D) -> Result<T, D::Error>
where
    T: Named,
    T::Err: Display,
    D: Deserializer<'de>,
{
    String::deserialize(d)?.parse().map_err(D::Error::custom)
}
