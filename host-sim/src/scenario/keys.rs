//! The keys every scenario table accepts, read from the loader's own types: serde's
//! derive hands each struct's accepted field names to the deserializer, and
//! [`fields`] catches them there. [`super::tables`] lists every table with them;
//! `docs/scenarios.md` is tested against that list, so a key the loader accepts cannot go
//! undocumented.

use serde::de::{self, Deserialize, Deserializer, Visitor};
use std::fmt;

/// The field names a `#[derive(Deserialize)]` struct `T` accepts (empty for other types).
pub fn fields<T: for<'de> Deserialize<'de>>() -> &'static [&'static str] {
    let mut probe = Probe(None);
    let _ = T::deserialize(&mut probe);
    probe.0.unwrap_or(&[])
}

/// A deserializer that records the fields of the first struct asked of it, then fails.
struct Probe(Option<&'static [&'static str]>);

#[derive(Debug)]
struct Stop;

impl fmt::Display for Stop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("probe")
    }
}

impl std::error::Error for Stop {}

impl de::Error for Stop {
    fn custom<M: fmt::Display>(_: M) -> Self {
        Stop
    }
}

impl<'de> Deserializer<'de> for &mut Probe {
    type Error = Stop;

    fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Stop> {
        Err(Stop)
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        fields: &'static [&'static str],
        _: V,
    ) -> Result<V::Value, Stop> {
        self.0 = Some(fields);
        Err(Stop)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
        option unit unit_struct newtype_struct seq tuple tuple_struct map enum identifier
        ignored_any
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn fields_are_read_from_the_derive() {
        #[derive(serde::Deserialize)]
        #[allow(dead_code)]
        struct Probed {
            half_size: f64,
            lanes: u8,
        }
        let f = super::fields::<Probed>();
        assert_eq!(f, ["half_size", "lanes"]);
        assert!(super::fields::<u32>().is_empty());
    }
}
