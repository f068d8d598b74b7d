//! Column values whose storage both backends share: JSON kept as text and flags kept as
//! 0/1 integers. sqlx's runtime-chosen driver (`Any`) maps only the plain types (integers,
//! floats, text, bytes, bool), so these two are spelled out here once.

use serde::Serialize;
use serde::de::DeserializeOwned;
use sqlx::any::{Any, AnyTypeInfo, AnyTypeInfoKind};
use sqlx::encode::IsNull;
use sqlx::error::BoxDynError;
use sqlx::{Database, Decode, Encode, Type, ValueRef};

/// A value stored as JSON text (`text` on both backends, never `jsonb`, so the stored bytes
/// and the API's echo of them are the same everywhere). Serialises as the value itself.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(transparent)]
pub struct Json<T>(pub T);

impl<T> Type<Any> for Json<T> {
    fn type_info() -> AnyTypeInfo {
        <String as Type<Any>>::type_info()
    }

    fn compatible(ty: &AnyTypeInfo) -> bool {
        <String as Type<Any>>::compatible(ty)
    }
}

impl<T: Serialize> Encode<'_, Any> for Json<T> {
    fn encode_by_ref(
        &self,
        buf: &mut <Any as Database>::ArgumentBuffer,
    ) -> Result<IsNull, BoxDynError> {
        let text = serde_json::to_string(&self.0)?;
        <String as Encode<'_, Any>>::encode(text, buf)
    }
}

impl<'r, T: DeserializeOwned> Decode<'r, Any> for Json<T> {
    fn decode(value: <Any as Database>::ValueRef<'r>) -> Result<Self, BoxDynError> {
        let text = <String as Decode<'r, Any>>::decode(value)?;
        Ok(Self(serde_json::from_str(&text)?))
    }
}

/// A yes/no column, stored as the integer 0 or 1 on both backends (a CHECK constraint
/// keeps it so) and read back as a `bool` (serialised as one).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(transparent)]
pub struct Flag(pub bool);

impl From<bool> for Flag {
    fn from(value: bool) -> Self {
        Self(value)
    }
}

impl From<Flag> for bool {
    fn from(flag: Flag) -> Self {
        flag.0
    }
}

impl Type<Any> for Flag {
    fn type_info() -> AnyTypeInfo {
        <i64 as Type<Any>>::type_info()
    }

    fn compatible(ty: &AnyTypeInfo) -> bool {
        ty.kind().is_integer() || ty.kind() == AnyTypeInfoKind::Bool
    }
}

impl Encode<'_, Any> for Flag {
    fn encode_by_ref(
        &self,
        buf: &mut <Any as Database>::ArgumentBuffer,
    ) -> Result<IsNull, BoxDynError> {
        <i64 as Encode<'_, Any>>::encode(i64::from(self.0), buf)
    }
}

impl<'r> Decode<'r, Any> for Flag {
    fn decode(value: <Any as Database>::ValueRef<'r>) -> Result<Self, BoxDynError> {
        if value.type_info().kind() == AnyTypeInfoKind::Bool {
            return Ok(Self(<bool as Decode<'r, Any>>::decode(value)?));
        }
        match <i64 as Decode<'r, Any>>::decode(value)? {
            0 => Ok(Self(false)),
            1 => Ok(Self(true)),
            other => Err(format!("{other} is not a flag (0 or 1)").into()),
        }
    }
}

/// An optional double bound as a parameter. sqlx 0.9's `Any` driver binds a `None` of
/// `f64` as a PostgreSQL `real` (float4) null; a statement first prepared with it keeps
/// that parameter type on the connection, and a later `Some` (sent as float8) is refused
/// with "incorrect binary data format". This binds the null as `double precision`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NullableDouble(pub Option<f64>);

impl Type<Any> for NullableDouble {
    fn type_info() -> AnyTypeInfo {
        <f64 as Type<Any>>::type_info()
    }
}

impl Encode<'_, Any> for NullableDouble {
    fn encode_by_ref(
        &self,
        buf: &mut <Any as Database>::ArgumentBuffer,
    ) -> Result<IsNull, BoxDynError> {
        match self.0 {
            Some(v) => <f64 as Encode<'_, Any>>::encode(v, buf),
            // The driver's two float kinds are swapped for nulls: a null of `f32`'s kind
            // is the one it sends as float8. (The PostgreSQL API tests catch a fix
            // upstream: the cohort insert would fail again.)
            None => <Option<f32> as Encode<'_, Any>>::encode(None, buf),
        }
    }
}

/// A latent as stored: its f32 values little-endian, one after another (`blob`/`bytea`).
pub fn latent_blob(latent: &[f32]) -> Vec<u8> {
    latent.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// The values of a stored latent (see [`latent_blob`]).
pub fn latent_values(blob: &[u8]) -> Vec<f32> {
    blob.chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latents_are_stored_as_little_endian_f32_and_read_back_exactly() {
        let latent = [1.0_f32, -2.25, f32::MIN_POSITIVE, 3.0e-8];
        let blob = latent_blob(&latent);
        assert_eq!(&blob[..8], &[0, 0, 0x80, 0x3f, 0, 0, 0x10, 0xc0]);
        assert_eq!(blob.len(), 16);
        assert_eq!(latent_values(&blob), latent);
    }
}
