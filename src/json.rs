//! Reading JSON: strictly (a key given twice is an error; a struct must be an object,
//! not an array of its fields in order), with every error at its field path and in
//! kea's words.

use crate::error::{Error, FieldError, member_path, plain_serde_error};
use serde::de::{
    self, DeserializeSeed, Deserializer, EnumAccess, IntoDeserializer, Unexpected, VariantAccess,
    Visitor,
    value::{MapDeserializer, SeqDeserializer},
};
use serde_json::Value;

/// `T` from a JSON value, a serde error located at its field path (`system.a[0]`) and
/// worded as kea's own ([`plain_serde_error`]: "missing field `x`" at `system`
/// is "missing: …" at `system.x`). `hints` say what a missing member is, by name.
/// Every request type the core reads is parsed with this.
pub fn from_value_at<T: serde::de::DeserializeOwned>(
    value: serde_json::Value,
    hints: &[(&str, &str)],
) -> Result<T, Error> {
    serde_path_to_error::deserialize(Objects(&value)).map_err(|e| {
        let path = path_string(e.path());
        let message = e.into_inner().to_string();
        Error::Invalid(vec![plain_serde_error(
            FieldError::new(path, message),
            hints,
        )])
    })
}

/// A deserializer's path as kea writes paths: `system.a[0]`, and a key that is not an
/// identifier quoted (`params["a.b"]`, [`member_path`]).
fn path_string(path: &serde_path_to_error::Path) -> String {
    use serde_path_to_error::Segment;
    let mut out = String::new();
    for segment in path {
        match segment {
            Segment::Seq { index } => out.push_str(&format!("[{index}]")),
            Segment::Map { key } => out = member_path(&out, key),
            Segment::Enum { variant } => out = member_path(&out, variant),
            Segment::Unknown => out = member_path(&out, "?"),
        }
    }
    out
}

/// JSON text as a value, refusing an object with the same key twice. serde_json keeps
/// the last one silently, so `{"model": A, …, "model": B}` would run B unannounced;
/// here it is an error with the key, line and column. A UTF-8 byte-order mark at the
/// start (which Windows editors write) is skipped, as RFC 8259 §8.1 allows, rather than
/// refused as "expected value at line 1 column 1". Every way into kea (HTTP bodies,
/// the command line's files, the browser's worker) parses with this.
pub fn parse_json(text: &[u8]) -> Result<serde_json::Value, serde_json::Error> {
    if let Some(form) = utf16(text) {
        return Err(de::Error::custom(format!(
            "the text is UTF-16 ({form}), and JSON is read as UTF-8 (RFC 8259 §8.1): save it as UTF-8"
        )));
    }
    let text = text.strip_prefix(UTF8_BOM).unwrap_or(text);
    if let Err(e) = std::str::from_utf8(text) {
        let before = &text[..e.valid_up_to()];
        let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
        let line_start = before
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |i| i + 1);
        let column = String::from_utf8_lossy(&before[line_start..])
            .chars()
            .count()
            + 1;
        return Err(de::Error::custom(format!(
            "the text is not UTF-8: the byte 0x{:02X} at line {line} column {column} is not valid UTF-8 there, and JSON is read as UTF-8 (RFC 8259 §8.1): save it as UTF-8 (a file from a Windows editor may be in a code page such as Windows-1252)",
            text[e.valid_up_to()]
        )));
    }
    let value = serde_json::from_slice::<StrictValue>(text)
        .map(|v| v.0)
        .map_err(|e| {
            let words = e.to_string();
            // serde_json's words for its nesting limit read as if the JSON were wrong.
            if words.starts_with("recursion limit exceeded") {
                de::Error::custom(format!(
                    "arrays and objects nested more than 128 deep, beyond what kea reads (the JSON itself may be valid) at line {} column {}",
                    e.line(),
                    e.column()
                ))
            } else if words.starts_with("unexpected end of hex escape")
                || words.starts_with("lone leading surrogate")
            {
                // Its words for an unpaired surrogate escape name neither the cause nor,
                // for a lone low surrogate ("leading"), the right half.
                de::Error::custom(format!(
                    "a \\u escape of half a UTF-16 surrogate pair with no matching half (RFC 8259 §7: a character beyond U+FFFF is written as \\uD800–\\uDBFF followed by \\uDC00–\\uDFFF; such a half alone is no character): write the character itself, or both halves, at line {} column {}",
                    e.line(),
                    e.column()
                ))
            } else {
                e
            }
        })?;
    if let Some((lit, line, column)) = first_underflow(text) {
        return Err(de::Error::custom(format!(
            "the number {lit} is below the smallest f64 (≈ 4.9e-324) and would be read as 0, at line {line} column {column}: write 0 if 0 is meant"
        )));
    }
    Ok(value)
}

/// Whether `lit`, a number's text, names a non-zero value that parsed as `x` = 0: it
/// underflows f64 (serde_json and Rust read `1e-400` as 0 without a word).
pub fn underflows(lit: &str, x: f64) -> bool {
    let mantissa = lit.split(['e', 'E']).next().unwrap_or(lit);
    x == 0.0 && mantissa.bytes().any(|b| (b'1'..=b'9').contains(&b))
}

/// The first number of a valid JSON text that [`underflows`], with its line and
/// column (characters, from 1). Only a literal with a negative exponent can.
fn first_underflow(text: &[u8]) -> Option<(String, usize, usize)> {
    let (mut i, mut line, mut line_start) = (0, 1, 0);
    while i < text.len() {
        match text[i] {
            b'"' => {
                // Skip the string (the text is valid JSON: it ends).
                i += 1;
                while i < text.len() && text[i] != b'"' {
                    i += if text[i] == b'\\' { 2 } else { 1 };
                }
                i += 1;
            }
            b'\n' => {
                line += 1;
                i += 1;
                line_start = i;
            }
            b'-' | b'0'..=b'9' => {
                let start = i;
                while i < text.len()
                    && matches!(text[i], b'-' | b'+' | b'.' | b'e' | b'E' | b'0'..=b'9')
                {
                    i += 1;
                }
                let lit = std::str::from_utf8(&text[start..i]).unwrap_or_default();
                if (lit.contains("e-") || lit.contains("E-"))
                    && lit.parse::<f64>().is_ok_and(|x| underflows(lit, x))
                {
                    let column = String::from_utf8_lossy(&text[line_start..start])
                        .chars()
                        .count()
                        + 1;
                    return Some((lit.to_string(), line, column));
                }
            }
            _ => i += 1,
        }
    }
    None
}

/// Whether the text is UTF-16 (as Windows editors and PowerShell's `>` write it),
/// and which byte order: a byte-order mark, or JSON's first character (ASCII) with a
/// zero byte beside it.
fn utf16(text: &[u8]) -> Option<&'static str> {
    match text {
        [0xFF, 0xFE, ..] => Some("little-endian, with a byte-order mark"),
        [0xFE, 0xFF, ..] => Some("big-endian, with a byte-order mark"),
        [a, 0, ..] if *a != 0 => Some("little-endian"),
        [0, b, ..] if *b != 0 => Some("big-endian"),
        _ => None,
    }
}

/// U+FEFF, the byte-order mark, in UTF-8.
const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// A [`serde_json::Value`] whose objects have distinct keys.
struct StrictValue(serde_json::Value);

impl<'de> serde::Deserialize<'de> for StrictValue {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::{Error, MapAccess, SeqAccess, Visitor};
        use serde_json::Value;
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = StrictValue;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a JSON value")
            }
            fn visit_bool<E>(self, b: bool) -> Result<StrictValue, E> {
                Ok(StrictValue(Value::Bool(b)))
            }
            fn visit_i64<E>(self, x: i64) -> Result<StrictValue, E> {
                Ok(StrictValue(x.into()))
            }
            fn visit_u64<E>(self, x: u64) -> Result<StrictValue, E> {
                Ok(StrictValue(x.into()))
            }
            fn visit_f64<E>(self, x: f64) -> Result<StrictValue, E> {
                Ok(StrictValue(x.into()))
            }
            fn visit_str<E>(self, s: &str) -> Result<StrictValue, E> {
                Ok(StrictValue(Value::String(s.to_string())))
            }
            fn visit_string<E>(self, s: String) -> Result<StrictValue, E> {
                Ok(StrictValue(Value::String(s)))
            }
            fn visit_unit<E>(self) -> Result<StrictValue, E> {
                Ok(StrictValue(Value::Null))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<StrictValue, A::Error> {
                let mut items = Vec::new();
                while let Some(StrictValue(v)) = seq.next_element()? {
                    items.push(v);
                }
                Ok(StrictValue(Value::Array(items)))
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<StrictValue, A::Error> {
                let mut object = serde_json::Map::new();
                while let Some(key) = map.next_key::<String>()? {
                    if object.contains_key(&key) {
                        return Err(A::Error::custom(format!(
                            "the key \"{key}\" appears twice in one object"
                        )));
                    }
                    let StrictValue(v) = map.next_value()?;
                    object.insert(key, v);
                }
                Ok(StrictValue(Value::Object(object)))
            }
        }
        d.deserialize_any(V)
    }
}

/// A whole number ≥ 0, also where written as a float (`1000.0`, `1e3`: Python's json
/// writes a float so), as every whole-number member of kea's requests reads it.
pub fn whole_u64(v: &Value) -> Option<u64> {
    match v.as_f64() {
        _ if v.is_u64() => v.as_u64(),
        Some(x) => whole_f64(x),
        None => None,
    }
}

/// A float that is a whole number in u64's range, as that number.
fn whole_f64(x: f64) -> Option<u64> {
    (x.fract() == 0.0 && (0.0..1.8e19).contains(&x)).then_some(x as u64)
}

/// A whole-number member whose kea range is `MIN..=MAX`: reads any whole number ≥ 0
/// (the range is checked with the request's other rules, so that every error is
/// reported at once), but a value of the wrong type (`2.5`, `-3`, `"9"`) is refused
/// naming the range — "expected a whole number from 2 to 64, got 2.5" — where a plain
/// integer's error would only say "≥ 0". For `#[serde(deserialize_with = …)]`.
pub fn whole_in<'de, D, T, const MIN: u64, const MAX: u64>(d: D) -> Result<T, D::Error>
where
    D: Deserializer<'de>,
    T: TryFrom<u64>,
{
    struct Whole<const MIN: u64, const MAX: u64>;
    impl<const MIN: u64, const MAX: u64> Visitor<'_> for Whole<MIN, MAX> {
        type Value = u64;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            if MAX == u64::MAX {
                write!(f, "a whole number from {MIN}")
            } else {
                write!(f, "a whole number from {MIN} to {MAX}")
            }
        }
        fn visit_u64<E: de::Error>(self, v: u64) -> Result<u64, E> {
            Ok(v)
        }
        fn visit_i64<E: de::Error>(self, v: i64) -> Result<u64, E> {
            u64::try_from(v).map_err(|_| E::invalid_value(Unexpected::Signed(v), &self))
        }
        fn visit_f64<E: de::Error>(self, v: f64) -> Result<u64, E> {
            whole_f64(v).ok_or_else(|| E::invalid_type(Unexpected::Float(v), &self))
        }
    }
    let v = d.deserialize_u64(Whole::<MIN, MAX>)?;
    // (Beyond T's range only for a usize on a 32-bit target: wasm.)
    T::try_from(v)
        .map_err(|_| de::Error::invalid_value(Unexpected::Unsigned(v), &Whole::<MIN, MAX>))
}

/// A JSON value read as serde_json reads a [`Value`], except that a struct (or a
/// struct variant) must be an object: serde's derived structs also accept an array of
/// the fields in order, so `"options": [0, false]` was read as `trace_points = 0,
/// steady_state_shortcut = false` — unannounced, where every schema says object.
struct Objects<'a>(&'a Value);

fn unexpected(v: &Value) -> Unexpected<'_> {
    match v {
        Value::Null => Unexpected::Unit,
        Value::Bool(b) => Unexpected::Bool(*b),
        Value::Number(n) => match (n.as_u64(), n.as_i64(), n.as_f64()) {
            (Some(u), _, _) => Unexpected::Unsigned(u),
            (_, Some(i), _) => Unexpected::Signed(i),
            (_, _, f) => Unexpected::Float(f.unwrap_or(f64::NAN)),
        },
        Value::String(s) => Unexpected::Str(s),
        Value::Array(_) => Unexpected::Seq,
        Value::Object(_) => Unexpected::Map,
    }
}

impl<'de> IntoDeserializer<'de, serde_json::Error> for Objects<'de> {
    type Deserializer = Self;
    fn into_deserializer(self) -> Self {
        self
    }
}

impl<'de> Objects<'de> {
    fn visit_object<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, serde_json::Error> {
        match self.0 {
            Value::Object(m) => visitor.visit_map(MapDeserializer::new(
                m.iter().map(|(k, v)| (k.as_str(), Objects(v))),
            )),
            other => Err(de::Error::invalid_type(unexpected(other), &visitor)),
        }
    }
}

impl<'de> Deserializer<'de> for Objects<'de> {
    type Error = serde_json::Error;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        match self.0 {
            Value::Null => visitor.visit_unit(),
            Value::Bool(b) => visitor.visit_bool(*b),
            Value::Number(n) => match (n.as_u64(), n.as_i64(), n.as_f64()) {
                (Some(u), _, _) => visitor.visit_u64(u),
                (_, Some(i), _) => visitor.visit_i64(i),
                (_, _, f) => visitor.visit_f64(f.unwrap_or(f64::NAN)),
            },
            Value::String(s) => visitor.visit_borrowed_str(s),
            Value::Array(a) => {
                // `end` refuses entries the visitor left: a fixed-length array
                // (`[t_from, t_to]`) took its first two of `[0, 0.5, 1]` and said
                // nothing of the third.
                let mut seq = SeqDeserializer::new(a.iter().map(Objects));
                let v = visitor.visit_seq(&mut seq)?;
                seq.end()?;
                Ok(v)
            }
            Value::Object(_) => self.visit_object(visitor),
        }
    }

    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        match self.0 {
            Value::Null => visitor.visit_none(),
            _ => visitor.visit_some(self),
        }
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        visitor.visit_newtype_struct(self)
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        self.visit_object(visitor)
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        match self.0 {
            Value::String(s) => visitor.visit_enum(s.as_str().into_deserializer()),
            Value::Object(m) if m.len() == 1 => {
                let (variant, value) = m
                    .iter()
                    .next()
                    .map(|(k, v)| (k.as_str(), v))
                    .unwrap_or(("", &Value::Null));
                visitor.visit_enum(Variant { variant, value })
            }
            Value::Object(_) => Err(de::Error::invalid_value(
                Unexpected::Map,
                &"map with a single key",
            )),
            other => Err(de::Error::invalid_type(
                unexpected(other),
                &"a string or an object with one member",
            )),
        }
    }

    // A whole number written with a fraction or an exponent (`1000.0`, `1e3`, as
    // Python's json writes a float) is that whole number, as `time.steps` reads it.
    fn deserialize_u64<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        match whole_u64(self.0) {
            Some(x) => visitor.visit_u64(x),
            None => self.deserialize_any(visitor),
        }
    }

    fn deserialize_u32<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        self.deserialize_u64(visitor)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u128 f32 f64 char str string bytes
        byte_buf unit unit_struct seq tuple tuple_struct map identifier ignored_any
    }
}

/// An externally tagged enum's `{"variant": value}`.
struct Variant<'a> {
    variant: &'a str,
    value: &'a Value,
}

impl<'de> EnumAccess<'de> for Variant<'de> {
    type Error = serde_json::Error;
    type Variant = Objects<'de>;
    fn variant_seed<S: DeserializeSeed<'de>>(
        self,
        seed: S,
    ) -> Result<(S::Value, Objects<'de>), serde_json::Error> {
        let variant = seed.deserialize(self.variant.into_deserializer())?;
        Ok((variant, Objects(self.value)))
    }
}

impl<'de> VariantAccess<'de> for Objects<'de> {
    type Error = serde_json::Error;
    fn unit_variant(self) -> Result<(), serde_json::Error> {
        match self.0 {
            Value::Null => Ok(()),
            other => Err(de::Error::invalid_type(unexpected(other), &"unit variant")),
        }
    }
    fn newtype_variant_seed<S: DeserializeSeed<'de>>(
        self,
        seed: S,
    ) -> Result<S::Value, serde_json::Error> {
        seed.deserialize(self)
    }
    fn tuple_variant<V: Visitor<'de>>(
        self,
        _len: usize,
        visitor: V,
    ) -> Result<V::Value, serde_json::Error> {
        self.deserialize_seq(visitor)
    }
    fn struct_variant<V: Visitor<'de>>(
        self,
        _fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, serde_json::Error> {
        self.visit_object(visitor)
    }
}

#[cfg(test)]
mod tests {
    use super::parse_json;
    use serde_json::json;

    #[test]
    fn a_leading_utf8_byte_order_mark_is_skipped_and_only_there() {
        assert_eq!(
            parse_json(b"\xEF\xBB\xBF{\"a\": [1]}").unwrap(),
            json!({"a": [1]})
        );
        // Anywhere else it is a character that JSON does not allow between tokens.
        assert!(parse_json(b"{\"a\": \xEF\xBB\xBF[1]}").is_err());
        assert!(parse_json(b"\xEF\xBB\xBF\xEF\xBB\xBF{}").is_err());
        // The strict reader's checks still apply after it.
        let e = parse_json(b"\xEF\xBB\xBF{\"a\": 1, \"a\": 2}").unwrap_err();
        assert!(e.to_string().contains("appears twice"), "{e}");
    }

    /// JSON nested beyond serde_json's 128 levels was "recursion limit exceeded",
    /// which reads as if the JSON were wrong.
    #[test]
    fn nesting_beyond_the_reader_is_named_as_its_limit() {
        let deep = format!("{}{}", "[".repeat(200), "]".repeat(200));
        let e = parse_json(deep.as_bytes()).unwrap_err().to_string();
        assert!(
            e.starts_with("arrays and objects nested more than 128 deep, beyond what kea reads"),
            "{e}"
        );
        assert!(e.contains("at line 1 column 128"), "{e}");
        let fine = format!("{}{}", "[".repeat(100), "]".repeat(100));
        assert!(parse_json(fine.as_bytes()).is_ok());
    }

    /// A literal below the smallest f64 was read as 0 without a word (an SKO of
    /// 1e-400 became a noise-free sensor), while one above the largest is refused.
    #[test]
    fn a_number_that_underflows_to_zero_is_refused_with_its_place() {
        let e = parse_json(b"{\"a\": [1, 2.5e-400],\n \"b\": \"1e-400\"}").unwrap_err();
        assert_eq!(
            e.to_string(),
            "the number 2.5e-400 is below the smallest f64 (≈ 4.9e-324) and would be read as 0, at line 1 column 11: write 0 if 0 is meant"
        );
        let e = parse_json(b"{\"s\": \"\\\" 1e-999\",\n  \"b\": -1E-330}").unwrap_err();
        assert!(
            e.to_string().contains("-1E-330 is below") && e.to_string().contains("line 2 column 8"),
            "{e}"
        );
        // Zero written any way, subnormals and strings are numbers as they were.
        let fine =
            parse_json(b"[0, 0.0, -0e-999, 0e5, 1e-320, 4.9e-324, 1e-300, \"1e-400\"]").unwrap();
        assert_eq!(fine[4], json!(1e-320));
        assert_eq!(fine[5].as_f64(), Some(5e-324));
        assert!(super::underflows("1e-400", 0.0) && !super::underflows("0.000e-400", 0.0));
    }

    /// An unpaired surrogate escape was "unexpected end of hex escape", or for a lone
    /// low surrogate "lone leading surrogate".
    #[test]
    fn an_unpaired_surrogate_escape_is_named_as_one() {
        for text in [
            r#"{"a": "\ud800x"}"#,
            r#"{"a": "\ud800"}"#,
            r#"{"a": "\udc00"}"#,
            r#"{"a": "\ud800\ud800"}"#,
        ] {
            let e = parse_json(text.as_bytes()).unwrap_err().to_string();
            assert!(
                e.starts_with("a \\u escape of half a UTF-16 surrogate pair with no matching half"),
                "{text}: {e}"
            );
            assert!(e.contains("at line 1 column"), "{text}: {e}");
        }
        let pair = parse_json(r#"{"a": "\ud83d\ude00"}"#.as_bytes()).unwrap();
        assert_eq!(pair, json!({"a": "\u{1F600}"}));
        let bad = parse_json(r#"{"a": "\u12zz"}"#.as_bytes()).unwrap_err();
        assert!(bad.to_string().starts_with("invalid escape"), "{bad}");
    }

    /// A UTF-16 text (PowerShell's `>` writes one) or a code-page text was reported
    /// by the CLI as "stream did not contain valid UTF-8", with no place and no cause.
    #[test]
    fn a_text_that_is_not_utf8_is_named_with_its_encoding_or_place() {
        let message = |bytes: &[u8]| parse_json(bytes).unwrap_err().to_string();
        let le: Vec<u8> = "{\"a\": 1}"
            .encode_utf16()
            .flat_map(u16::to_le_bytes)
            .collect();
        let be: Vec<u8> = "{\"a\": 1}"
            .encode_utf16()
            .flat_map(u16::to_be_bytes)
            .collect();
        for (bytes, form) in [
            (
                [&[0xFF, 0xFE][..], &le].concat(),
                "little-endian, with a byte-order mark",
            ),
            (
                [&[0xFE, 0xFF][..], &be].concat(),
                "big-endian, with a byte-order mark",
            ),
            (le, "little-endian"),
            (be, "big-endian"),
        ] {
            assert!(
                message(&bytes).starts_with(&format!(
                    "the text is UTF-16 ({form}), and JSON is read as UTF-8"
                )),
                "{}",
                message(&bytes)
            );
        }
        // é in Windows-1252 (0xE9) after é in UTF-8 (two bytes, one column).
        let m = message(b"{\n  \"a\": \"\xC3\xA9\xE9\"}");
        assert!(
            m.starts_with(
                "the text is not UTF-8: the byte 0xE9 at line 2 column 10 is not valid UTF-8 there"
            ),
            "{m}"
        );
        // Valid UTF-8 beyond ASCII is read.
        assert_eq!(
            parse_json("{\"é\": \"Φ\"}".as_bytes()).unwrap(),
            json!({"é": "Φ"})
        );
    }
}
