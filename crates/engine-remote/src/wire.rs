//! The protocol's framing (docs/engine-protocol.md): vectors of `f64` as
//! the hexadecimal text of their little-endian IEEE 754 bytes, and the
//! located reading of replies (a field missing, of the wrong type, of the
//! wrong length, or not finite is an error naming the request and field).

use serde_json::{Map, Value};

/// The protocol version this side speaks.
pub const PROTOCOL_VERSION: u64 = 1;

/// `values` as the hexadecimal text of their little-endian bytes (16
/// digits a number).
pub fn bits(values: &[f64]) -> String {
    const HEX: &[u8; 16] = b"0123456789abcdef";
    let mut out = String::with_capacity(values.len() * 16);
    for v in values {
        for b in v.to_le_bytes() {
            out.push(HEX[(b >> 4) as usize] as char);
            out.push(HEX[(b & 15) as usize] as char);
        }
    }
    out
}

/// The value of each hexadecimal digit, 16 for any other byte.
const HEX_VALUE: [u8; 256] = {
    let mut table = [16u8; 256];
    let mut i = 0;
    while i < 16 {
        table[b"0123456789abcdef"[i] as usize] = i as u8;
        table[b"0123456789ABCDEF"[i] as usize] = i as u8;
        i += 1;
    }
    table
};

/// The numbers of a [`bits`] text; the message says what is wrong.
pub fn floats(text: &str) -> Result<Vec<f64>, String> {
    let b = text.as_bytes();
    if !b.len().is_multiple_of(16) {
        return Err(format!(
            "{} hex digits, not a whole number of 16-digit doubles",
            b.len()
        ));
    }
    // A replay's readings come back as one long text: a table lookup a
    // digit, the offending digit found only when there is one.
    let mut out = Vec::with_capacity(b.len() / 16);
    let mut bad = 0u8;
    for chunk in b.chunks_exact(16) {
        let mut bytes = [0u8; 8];
        for (byte, pair) in bytes.iter_mut().zip(chunk.chunks_exact(2)) {
            let (hi, lo) = (HEX_VALUE[pair[0] as usize], HEX_VALUE[pair[1] as usize]);
            bad |= hi | lo;
            *byte = hi << 4 | (lo & 15);
        }
        out.push(f64::from_le_bytes(bytes));
    }
    if bad & 16 != 0 {
        let at = b
            .iter()
            .position(|&c| HEX_VALUE[c as usize] == 16)
            .expect("a byte that is not a hex digit");
        return Err(format!("'{}' at {at} is not a hex digit", b[at] as char));
    }
    Ok(out)
}

/// A reply's `ok` object, read field by field with errors that name the
/// request and the field.
pub struct Reply<'a> {
    /// The request's `op`, for messages.
    pub op: &'a str,
    /// The `ok` object.
    pub fields: &'a Map<String, Value>,
}

impl<'a> Reply<'a> {
    fn missing(&self, key: &str, what: &str) -> String {
        format!("the reply to \"{}\" has no {what} field \"{key}\"", self.op)
    }

    /// A field as it is.
    pub fn value(&self, key: &str) -> Option<&'a Value> {
        self.fields.get(key).filter(|v| !v.is_null())
    }

    /// A text field.
    pub fn text(&self, key: &str) -> Result<&'a str, String> {
        self.fields
            .get(key)
            .and_then(Value::as_str)
            .ok_or_else(|| self.missing(key, "text"))
    }

    /// A plain JSON number (only in `hello` and stability issues).
    pub fn number(&self, key: &str) -> Result<f64, String> {
        self.fields
            .get(key)
            .and_then(Value::as_f64)
            .ok_or_else(|| self.missing(key, "number"))
    }

    /// An array field.
    pub fn array(&self, key: &str) -> Result<&'a Vec<Value>, String> {
        self.fields
            .get(key)
            .and_then(Value::as_array)
            .ok_or_else(|| self.missing(key, "array"))
    }

    /// An object field.
    pub fn object(&self, key: &str) -> Result<Reply<'a>, String> {
        let fields = self
            .fields
            .get(key)
            .and_then(Value::as_object)
            .ok_or_else(|| self.missing(key, "object"))?;
        Ok(Reply {
            op: self.op,
            fields,
        })
    }

    /// A vector of `len` finite numbers as bits (`len` `None`: any
    /// length); `what` names them in the message about a non-finite one.
    pub fn vector(&self, key: &str, len: Option<usize>) -> Result<Vec<f64>, String> {
        let text = self.text(key)?;
        let v = floats(text)
            .map_err(|e| format!("the reply to \"{}\": field \"{key}\": {e}", self.op))?;
        if let Some(n) = len {
            if v.len() != n {
                return Err(format!(
                    "the reply to \"{}\": field \"{key}\" has {} numbers, {n} expected",
                    self.op,
                    v.len()
                ));
            }
        }
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(format!(
                "the reply to \"{}\": {key}[{i}] is {} (not finite)",
                self.op, v[i]
            ));
        }
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_travel_exactly() {
        let v = [
            1.0,
            -0.0,
            f64::MIN_POSITIVE / 8.0,
            0.1 + 0.2,
            f64::MAX,
            -1e-300,
        ];
        let text = bits(&v);
        assert_eq!(&text[..16], "000000000000f03f");
        let back = floats(&text).unwrap();
        for (a, b) in v.iter().zip(&back) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
        assert_eq!(floats(&text.to_uppercase()).unwrap(), back);
        assert!(floats("00").unwrap_err().contains("not a whole number"));
        assert!(floats("000000000000f03g")
            .unwrap_err()
            .contains("'g' at 15 is not a hex digit"));
    }

    #[test]
    fn replies_name_the_field() {
        let v: Value = serde_json::json!({"q": bits(&[1.0, f64::NAN]), "t": 3});
        let r = Reply {
            op: "step",
            fields: v.as_object().unwrap(),
        };
        assert_eq!(
            r.vector("q", Some(2)).unwrap_err(),
            "the reply to \"step\": q[1] is NaN (not finite)"
        );
        assert!(r
            .vector("q", Some(3))
            .unwrap_err()
            .contains("has 2 numbers, 3 expected"));
        assert_eq!(
            r.text("t").unwrap_err(),
            "the reply to \"step\" has no text field \"t\""
        );
    }
}
