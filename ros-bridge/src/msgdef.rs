//! The message definitions of `ros/skinbox_msgs/msg/*.msg`, compiled in: their schema text
//! as MCAP and Foxglove carry it (`ros2msg`: the message, then each message it uses after a
//! line of `=` and `MSG: package/Name`), a parser of the `.msg` syntax and a CDR decoder
//! driven by the parsed definitions. The decoder reads what [`crate::msg`] writes without
//! knowing the Rust side: the one-definition test holds both against each other.

use std::collections::BTreeMap;

/// The ROS 2 interface package of the messages.
pub const PACKAGE: &str = "skinbox_msgs";

/// Every definition the messages use, by `package/Name`: the package's `.msg` files and
/// `builtin_interfaces/Time` (as ROS 2 defines it).
pub const DEFINITIONS: &[(&str, &str)] = &[
    (
        "skinbox_msgs/CellSample",
        include_str!("../../ros/skinbox_msgs/msg/CellSample.msg"),
    ),
    (
        "skinbox_msgs/CellSampleBatch",
        include_str!("../../ros/skinbox_msgs/msg/CellSampleBatch.msg"),
    ),
    (
        "skinbox_msgs/PortCounters",
        include_str!("../../ros/skinbox_msgs/msg/PortCounters.msg"),
    ),
    (
        "skinbox_msgs/BoxStatus",
        include_str!("../../ros/skinbox_msgs/msg/BoxStatus.msg"),
    ),
    (
        "skinbox_msgs/PortActivity",
        include_str!("../../ros/skinbox_msgs/msg/PortActivity.msg"),
    ),
    (
        "skinbox_msgs/SkinActivity",
        include_str!("../../ros/skinbox_msgs/msg/SkinActivity.msg"),
    ),
    (
        "builtin_interfaces/Time",
        "# Time since the Unix epoch (or a clock's origin).\nint32 sec\nuint32 nanosec\n",
    ),
];

/// How many values a field holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arity {
    /// One value.
    One,
    /// A fixed-size array `T[N]`.
    Fixed(usize),
    /// An unbounded sequence `T[]`.
    Unbounded,
}

/// One field of a message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldDef {
    /// A primitive type (`uint16`, `float64`, `string`, ...) or a message's
    /// `package/Name`.
    pub ty: String,
    /// One value, an array or a sequence.
    pub arity: Arity,
    /// The field's name.
    pub name: String,
}

/// One constant of a message: type, name and value as written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConstantDef {
    /// Its primitive type.
    pub ty: String,
    /// Its name.
    pub name: String,
    /// Its value as written in the `.msg` file.
    pub value: String,
}

/// A parsed `.msg` file.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MsgDef {
    /// The fields in order.
    pub fields: Vec<FieldDef>,
    /// The constants in order.
    pub constants: Vec<ConstantDef>,
}

const PRIMITIVES: &[&str] = &[
    "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
    "uint64", "float32", "float64", "string",
];

/// Parses the text of a `.msg` file of `package`; an error names the line.
pub fn parse(package: &str, text: &str) -> Result<MsgDef, String> {
    let mut def = MsgDef::default();
    for (n, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let bad = || {
            format!(
                "line {}: {raw:?} is no `type name` nor `type NAME=value`",
                n + 1
            )
        };
        let (ty, rest) = line.split_once(char::is_whitespace).ok_or_else(bad)?;
        let rest = rest.trim();
        if let Some((name, value)) = rest.split_once('=') {
            def.constants.push(ConstantDef {
                ty: ty.to_string(),
                name: name.trim().to_string(),
                value: value.trim().to_string(),
            });
            continue;
        }
        if rest.contains(char::is_whitespace) {
            return Err(format!(
                "line {}: default values are not used here: {raw:?}",
                n + 1
            ));
        }
        let (base, arity) = match ty.split_once('[') {
            None => (ty, Arity::One),
            Some((base, "]")) => (base, Arity::Unbounded),
            Some((base, size)) => {
                let size = size
                    .strip_suffix(']')
                    .and_then(|s| s.parse().ok())
                    .ok_or_else(bad)?;
                (base, Arity::Fixed(size))
            }
        };
        let ty = if PRIMITIVES.contains(&base) || base.contains('/') {
            base.to_string()
        } else {
            format!("{package}/{base}")
        };
        def.fields.push(FieldDef {
            ty,
            arity,
            name: rest.to_string(),
        });
    }
    Ok(def)
}

/// The text of the definition `package/Name`.
pub fn definition_text(name: &str) -> Option<&'static str> {
    DEFINITIONS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, t)| *t)
}

/// The parsed definition `package/Name`.
pub fn definition(name: &str) -> Result<MsgDef, String> {
    let text = definition_text(name).ok_or_else(|| format!("no definition of {name}"))?;
    let package = name.split('/').next().unwrap_or(PACKAGE);
    parse(package, text).map_err(|e| format!("{name}: {e}"))
}

/// The `ros2msg` schema text of `package/Name` as rosbag2 and Foxglove expect it: its
/// definition, then every message it uses (depth first, each once) after a line of 80 `=`
/// and `MSG: package/Name`.
pub fn schema_text(name: &str) -> Result<String, String> {
    fn uses(name: &str, seen: &mut Vec<String>) -> Result<(), String> {
        for f in definition(name)?.fields {
            if f.ty.contains('/') && !seen.contains(&f.ty) {
                seen.push(f.ty.clone());
                uses(&f.ty, seen)?;
            }
        }
        Ok(())
    }
    let mut text = definition_text(name)
        .ok_or_else(|| format!("no definition of {name}"))?
        .to_string();
    let mut seen = Vec::new();
    uses(name, &mut seen)?;
    for dep in seen {
        text.push_str(&"=".repeat(80));
        text.push_str("\nMSG: ");
        text.push_str(&dep);
        text.push('\n');
        text.push_str(definition_text(&dep).unwrap_or(""));
    }
    Ok(text)
}

/// A decoded value, or the value a Rust message says it holds ([`crate::msg::RosMessage`]).
#[derive(Debug, Clone)]
pub enum Value {
    /// `bool`.
    Bool(bool),
    /// `uint8` (and `byte`, `char`).
    U8(u8),
    /// `uint16`.
    U16(u16),
    /// `uint32`.
    U32(u32),
    /// `uint64`.
    U64(u64),
    /// `int32`.
    I32(i32),
    /// `int64`.
    I64(i64),
    /// `float64`.
    F64(f64),
    /// `string`.
    String(String),
    /// An array or a sequence.
    Array(Vec<Value>),
    /// A message: its fields by name, in order.
    Message(Vec<(String, Value)>),
}

impl PartialEq for Value {
    /// Equal values; floats bit for bit (so NaN equals NaN).
    fn eq(&self, other: &Value) -> bool {
        use Value::*;
        match (self, other) {
            (Bool(a), Bool(b)) => a == b,
            (U8(a), U8(b)) => a == b,
            (U16(a), U16(b)) => a == b,
            (U32(a), U32(b)) => a == b,
            (U64(a), U64(b)) => a == b,
            (I32(a), I32(b)) => a == b,
            (I64(a), I64(b)) => a == b,
            (F64(a), F64(b)) => a.to_bits() == b.to_bits(),
            (String(a), String(b)) => a == b,
            (Array(a), Array(b)) => a == b,
            (Message(a), Message(b)) => a == b,
            _ => false,
        }
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize, align: bool) -> Result<&[u8], String> {
        if align {
            let pos = self.at - 4;
            self.at += (n - pos % n) % n;
        }
        let end = self.at + n;
        let s = self
            .bytes
            .get(self.at..end)
            .ok_or_else(|| format!("payload ends at {} before {end}", self.bytes.len()))?;
        self.at = end;
        Ok(s)
    }

    fn u32(&mut self) -> Result<u32, String> {
        let b = self.take(4, true)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn primitive(&mut self, ty: &str) -> Result<Value, String> {
        macro_rules! le {
            ($t:ty, $n:expr) => {{
                let b = self.take($n, true)?;
                <$t>::from_le_bytes(b.try_into().map_err(|_| "short".to_string())?)
            }};
        }
        Ok(match ty {
            "bool" => Value::Bool(self.take(1, false)?[0] != 0),
            "uint8" | "byte" | "char" => Value::U8(self.take(1, false)?[0]),
            "uint16" => Value::U16(le!(u16, 2)),
            "uint32" => Value::U32(le!(u32, 4)),
            "uint64" => Value::U64(le!(u64, 8)),
            "int32" => Value::I32(le!(i32, 4)),
            "int64" => Value::I64(le!(i64, 8)),
            "float64" => Value::F64(le!(f64, 8)),
            "string" => {
                let n = self.u32()? as usize;
                let b = self.take(n, false)?;
                let (text, nul) = b.split_at(n.saturating_sub(1));
                if nul != [0] {
                    return Err("string without its NUL".into());
                }
                Value::String(String::from_utf8(text.to_vec()).map_err(|e| e.to_string())?)
            }
            other => return Err(format!("type {other} is not read here")),
        })
    }

    fn one(&mut self, ty: &str) -> Result<Value, String> {
        if ty.contains('/') {
            self.message(ty)
        } else {
            self.primitive(ty)
        }
    }

    fn message(&mut self, name: &str) -> Result<Value, String> {
        let def = definition(name)?;
        let mut fields = Vec::with_capacity(def.fields.len());
        for f in &def.fields {
            let v = match f.arity {
                Arity::One => self.one(&f.ty)?,
                Arity::Fixed(n) => {
                    Value::Array((0..n).map(|_| self.one(&f.ty)).collect::<Result<_, _>>()?)
                }
                Arity::Unbounded => {
                    let n = self.u32()? as usize;
                    if n > self.bytes.len() {
                        return Err(format!(
                            "{}: sequence of {n} in a payload of {}",
                            f.name,
                            self.bytes.len()
                        ));
                    }
                    Value::Array((0..n).map(|_| self.one(&f.ty)).collect::<Result<_, _>>()?)
                }
            };
            fields.push((f.name.clone(), v));
        }
        Ok(Value::Message(fields))
    }
}

/// Decodes a little-endian CDR payload of the message `package/Name` by its parsed
/// definition; every byte must be used.
pub fn decode(name: &str, payload: &[u8]) -> Result<Value, String> {
    if payload.get(..4) != Some(&crate::cdr::CDR_LE_HEADER[..]) {
        return Err("no little-endian CDR encapsulation header".into());
    }
    let mut r = Reader {
        bytes: payload,
        at: 4,
    };
    let v = r.message(name)?;
    if r.at != payload.len() {
        return Err(format!("{} bytes left after {name}", payload.len() - r.at));
    }
    Ok(v)
}

/// The constants of every definition, by `package/Name` and constant name.
pub fn constants() -> Result<BTreeMap<(String, String), ConstantDef>, String> {
    let mut out = BTreeMap::new();
    for (name, _) in DEFINITIONS {
        for c in definition(name)?.constants {
            out.insert((name.to_string(), c.name.clone()), c);
        }
    }
    Ok(out)
}
