//! Internally tagged JSON objects, `{"type": "quad", "corners": ...}`, read
//! as one of several structs without losing where an error is.
//!
//! serde's own `#[serde(tag = "type")]` first reads the whole object into a
//! buffer (it cannot know the variant before it has seen "type"), and an
//! error inside the buffered object then names neither its field nor its
//! line: `objects[1].shape: unknown field` at the object's closing brace.
//! Here, when "type" comes first (as every scene writes it), the rest of the
//! object streams straight into the variant's struct, so the error is
//! `objects[1].shape.cornerz` at its own line. Fields before a later "type"
//! are buffered as JSON values and handed over first: still correct, only
//! their errors lose the line.

use serde::de::{self, value::MapAccessDeserializer, DeserializeSeed, IntoDeserializer, MapAccess, Visitor};
use serde::Deserializer;
use std::fmt;
use std::marker::PhantomData;

/// An enum read from an object whose "type" names the variant.
pub trait Tagged: Sized {
    /// What the object is, for "invalid type" errors.
    const EXPECTING: &'static str;
    /// The values "type" may take.
    const TAGS: &'static [&'static str];
    /// The variant `tag`, read from the rest of the object.
    fn variant<'de, D: Deserializer<'de>>(tag: &str, rest: D) -> Result<Self, D::Error>;
}

/// `Deserialize::deserialize` for a `Tagged` enum.
pub fn deserialize<'de, D: Deserializer<'de>, T: Tagged>(d: D) -> Result<T, D::Error> {
    d.deserialize_map(TaggedVisitor(PhantomData))
}

/// `Tagged` and `Deserialize` for an enum of one-struct variants:
/// `tagged_enum!(ShapeSpec, "a shape", { "quad" => Quad(QuadSpec), ... })`.
macro_rules! tagged_enum {
    ($name:ident, $what:literal, { $($tag:literal => $variant:ident($spec:ty)),+ $(,)? }) => {
        impl $crate::scene::tagged::Tagged for $name {
            const EXPECTING: &'static str = $what;
            const TAGS: &'static [&'static str] = &[$($tag),+];
            fn variant<'de, D: serde::Deserializer<'de>>(tag: &str, rest: D) -> Result<Self, D::Error> {
                match tag {
                    $($tag => <$spec as serde::Deserialize>::deserialize(rest).map(Self::$variant),)+
                    _ => Err(serde::de::Error::unknown_variant(tag, Self::TAGS)),
                }
            }
        }
        impl<'de> serde::Deserialize<'de> for $name {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                $crate::scene::tagged::deserialize(d)
            }
        }
    };
}
pub(crate) use tagged_enum;

struct TaggedVisitor<T>(PhantomData<T>);

impl<'de, T: Tagged> Visitor<'de> for TaggedVisitor<T> {
    type Value = T;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{} (an object with a \"type\")", T::EXPECTING)
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<T, A::Error> {
        let mut before = Vec::new();
        while let Some(key) = map.next_key::<String>()? {
            if key == "type" {
                let tag = map.next_value_seed(Tag(T::TAGS))?;
                let rest = Rest { before: before.into_iter(), value: None, map };
                return T::variant(&tag, MapAccessDeserializer::new(rest));
            }
            before.push((key, map.next_value::<serde_json::Value>()?));
        }
        Err(de::Error::missing_field("type"))
    }
}

/// The value of "type", checked against the tags where it stands (so an
/// unknown one is reported at its own line, as field `type`).
struct Tag(&'static [&'static str]);

impl<'de> DeserializeSeed<'de> for Tag {
    type Value = String;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<String, D::Error> {
        let tag = <String as serde::Deserialize>::deserialize(d)?;
        match self.0.contains(&tag.as_str()) {
            true => Ok(tag),
            false => Err(de::Error::unknown_variant(&tag, self.0)),
        }
    }
}

/// The object after its "type": the fields buffered before it, then the
/// ones still streaming.
struct Rest<A> {
    before: std::vec::IntoIter<(String, serde_json::Value)>,
    /// The value of the buffered key just handed out.
    value: Option<serde_json::Value>,
    map: A,
}

impl<'de, A: MapAccess<'de>> MapAccess<'de> for Rest<A> {
    type Error = A::Error;

    fn next_key_seed<K: DeserializeSeed<'de>>(&mut self, seed: K) -> Result<Option<K::Value>, A::Error> {
        match self.before.next() {
            Some((key, value)) => {
                self.value = Some(value);
                seed.deserialize(key.into_deserializer()).map(Some)
            }
            None => self.map.next_key_seed(seed),
        }
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, A::Error> {
        match self.value.take() {
            Some(value) => seed.deserialize(value).map_err(de::Error::custom),
            None => self.map.next_value_seed(seed),
        }
    }
}

#[cfg(test)]
mod tests {
    use serde::Deserialize;

    #[derive(Debug, PartialEq, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Disk {
        radius: f32,
        #[serde(default)]
        inward: bool,
    }

    #[derive(Debug, PartialEq, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Point {
        at: [f32; 2],
    }

    #[derive(Debug, PartialEq)]
    enum Shape {
        Disk(Disk),
        Point(Point),
    }

    tagged_enum!(Shape, "a test shape", { "disk" => Disk(Disk), "point" => Point(Point) });

    /// (value, error as `path: message (line L column C)`).
    fn parse(text: &str) -> Result<Vec<Shape>, String> {
        let de = &mut serde_json::Deserializer::from_str(text);
        serde_path_to_error::deserialize(de).map_err(|e| {
            let path = e.path().to_string();
            format!("{path}: {}", e.into_inner())
        })
    }

    #[test]
    fn type_first_or_last_reads_the_same() {
        let first = parse(r#"[{"type": "disk", "radius": 2, "inward": true}, {"type": "point", "at": [1, 2]}]"#);
        let last = parse(r#"[{"radius": 2, "inward": true, "type": "disk"}, {"at": [1, 2], "type": "point"}]"#);
        let want = vec![Shape::Disk(Disk { radius: 2.0, inward: true }), Shape::Point(Point { at: [1.0, 2.0] })];
        assert_eq!(first, Ok(want));
        assert_eq!(last, first);
        let middle = parse(r#"[{"radius": 2, "type": "disk", "inward": true}]"#).unwrap();
        assert_eq!(middle, vec![Shape::Disk(Disk { radius: 2.0, inward: true })]);
    }

    #[test]
    fn errors_name_the_field_and_its_line() {
        let e = parse("[{\"type\": \"disk\",\n \"radius\": \"2\",\n \"inward\": true}]").unwrap_err();
        assert_eq!(e, "[0].radius: invalid type: string \"2\", expected f32 at line 2 column 14");
        let e = parse("[{\"type\": \"disk\",\n \"radiuz\": 2}]").unwrap_err();
        assert!(e.starts_with("[0].radiuz: unknown field `radiuz`, expected `radius` or `inward` at line 2"), "{e}");
        let e = parse("[{\"type\":\n \"square\", \"radius\": 2}]").unwrap_err();
        assert_eq!(e, "[0].type: unknown variant `square`, expected `disk` or `point` at line 2 column 9");
        let e = parse(r#"[{"radius": 2}]"#).unwrap_err();
        assert!(e.starts_with("[0]: missing field `type`"), "{e}");
        // Read ahead of "type": the error names the object, not the field.
        let e = parse(r#"[{"radius": "2", "type": "disk"}]"#).unwrap_err();
        assert!(e.starts_with("[0]: invalid type: string \"2\", expected f32"), "{e}");
        let e = parse(r#"[[1, 2]]"#).unwrap_err();
        assert!(e.contains("expected a test shape (an object with a \"type\")"), "{e}");
    }
}
