//! PyTorch's legacy serialisation of one float64 tensor (`torch.save`
//! before PyTorch 1.6, or with `_use_new_zipfile_serialization=False`),
//! read without Python: the layout of the ContactNets `N.pt` files, and
//! nothing more.
//!
//! A legacy file is five pickles (protocol 2) and the raw storage:
//!
//! ```text
//! pickle 1  the magic number 0x1950a86a20f9469cfc6c (LONG1)
//! pickle 2  the legacy protocol version, 1001
//! pickle 3  system info: {"protocol_version": 1001, "little_endian": True, "type_sizes": {...}}
//! pickle 4  the tensor: torch._utils._rebuild_tensor_v2(storage, offset, size, stride,
//!           requires_grad, OrderedDict()), the storage a persistent id
//!           ("storage", torch.DoubleStorage, key, location, element count, None)
//! pickle 5  the storage keys: [key]
//! storage   an i64 element count, then the elements (little-endian f64)
//! ```
//!
//! The pickles are run on a small stack machine that knows only the
//! opcodes such a file uses (PROTO, LONG1, BININT1/2, BININT, BINUNICODE,
//! GLOBAL, the empty containers, MARK, TUPLE and TUPLE1-3, SETITEMS, APPEND,
//! NONE, NEWTRUE/NEWFALSE, BINPUT, BINPERSID, REDUCE, STOP); it calls no
//! function and builds no object, it only checks that the calls are the
//! ones above. Anything else is an [`ImportError`] naming the file, the
//! byte offset and the field: an unknown opcode, another storage type
//! (`torch.FloatStorage`: float32), a storage offset or strides that are
//! not those of a contiguous tensor, a truncated storage, bytes after it.
//! Every length read from the file is checked against the bytes left
//! before anything is allocated.

use realitygap_data::ImportError;
use std::path::Path;

/// The magic number of the legacy format, as LONG1's little-endian bytes
/// (0x1950a86a20f9469cfc6c).
const MAGIC: [u8; 10] = [0x6c, 0xfc, 0x9c, 0x46, 0xf9, 0x20, 0x6a, 0xa8, 0x50, 0x19];
/// The legacy format's protocol version.
const LEGACY_VERSION: i64 = 1001;
/// Deepest nesting of containers accepted (the tensor's pickle nests 4).
const MAX_DEPTH: usize = 8;

/// A tensor read from a legacy `.pt` file: contiguous float64 values.
#[derive(Debug, Clone, PartialEq)]
pub struct PtTensor {
    /// The tensor's size, outermost dimension first.
    pub shape: Vec<usize>,
    /// The values in row-major order (`shape`'s product of them).
    pub values: Vec<f64>,
    /// Byte offset of the size tuple's first opcode in the file (for
    /// messages).
    pub shape_at: usize,
    /// Byte offset of the first value in the file: value `i` is at
    /// `values_at + 8 i`.
    pub values_at: usize,
}

/// A pickled value, as far as this reader needs one.
#[derive(Debug, Clone, PartialEq)]
enum Value {
    /// An int (BININT1, BININT2, BININT).
    Int(i64),
    /// A LONG1 integer, its little-endian two's-complement bytes.
    Long(Vec<u8>),
    /// A str.
    Str(String),
    /// True or False.
    Bool(bool),
    /// None.
    None,
    /// A module global: module and name.
    Global(String, String),
    /// A tuple.
    Tuple(Vec<Item>),
    /// A list.
    List(Vec<Item>),
    /// A dict, its items in order.
    Dict(Vec<(Item, Item)>),
    /// A persistent id (BINPERSID): what it names.
    Persistent(Box<Item>),
    /// A call (REDUCE) of a callable with arguments: not made, kept.
    Call(Box<Item>, Vec<Item>),
}

/// A value and where it starts in the file.
#[derive(Debug, Clone, PartialEq)]
struct Item {
    /// Byte offset of its first opcode (a container's MARK or first
    /// element, a call's callable).
    at: usize,
    /// Nesting depth: 0 for a scalar.
    depth: usize,
    value: Value,
}

impl Item {
    /// What kind of value it is, for messages.
    fn kind(&self) -> String {
        match &self.value {
            Value::Int(i) => format!("the int {i}"),
            Value::Long(_) => "a long int".into(),
            Value::Str(s) => format!("the str {:?}", clip(s)),
            Value::Bool(b) => if *b { "True" } else { "False" }.to_string(),
            Value::None => "None".into(),
            Value::Global(m, n) => format!("{m}.{n}"),
            Value::Tuple(v) => format!("a tuple of {}", v.len()),
            Value::List(v) => format!("a list of {}", v.len()),
            Value::Dict(v) => format!("a dict of {}", v.len()),
            Value::Persistent(_) => "a persistent id".into(),
            Value::Call(f, a) => format!("a call of {} with {} arguments", f.kind(), a.len()),
        }
    }
}

/// At most 40 characters of a str, for messages.
fn clip(s: &str) -> String {
    let mut out: String = s.chars().take(40).collect();
    if s.chars().count() > 40 {
        out.push_str("...");
    }
    out
}

/// A stack slot: a value, or a MARK.
#[derive(Debug)]
enum Slot {
    Mark(usize),
    Item(Item),
}

/// The reader: the file's bytes and a position in them.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    file: &'a Path,
}

impl<'a> Reader<'a> {
    /// An error at byte `at`, about `field`.
    fn error(&self, at: usize, field: &str, message: impl Into<String>) -> ImportError {
        ImportError::new(self.file, message).with_field(format!("byte {at} ({field})"))
    }

    /// The next `n` bytes, for `what`; an error when the file ends first.
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ImportError> {
        let left = self.bytes.len() - self.pos;
        if n > left {
            return Err(self.error(
                self.pos,
                what,
                format!(
                    "the file is truncated: {what} needs {n} bytes, the file ends {left} bytes later (at byte {})",
                    self.bytes.len()
                ),
            ));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn u8(&mut self, what: &str) -> Result<u8, ImportError> {
        Ok(self.take(1, what)?[0])
    }

    fn u16(&mut self, what: &str) -> Result<u16, ImportError> {
        let b = self.take(2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn u32(&mut self, what: &str) -> Result<u32, ImportError> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// A GLOBAL's line: text up to `\n`, within the bytes left.
    fn line(&mut self, what: &str) -> Result<String, ImportError> {
        let at = self.pos;
        let rest = &self.bytes[self.pos..];
        let Some(end) = rest.iter().take(256).position(|&b| b == b'\n') else {
            let message = if rest.len() < 256 {
                format!(
                    "the file is truncated: it ends inside a global's name (at byte {})",
                    self.bytes.len()
                )
            } else {
                "expected a name ending in a line break within 256 bytes".to_string()
            };
            return Err(self.error(at, what, message));
        };
        let text = std::str::from_utf8(&rest[..end])
            .ok()
            .filter(|t| t.chars().all(|c| c.is_ascii_graphic()))
            .ok_or_else(|| self.error(at, what, "a global's name is not printable ASCII"))?;
        self.pos += end + 1;
        Ok(text.to_string())
    }

    /// Runs one pickle up to its STOP and returns its value. `what` names
    /// the pickle in messages.
    fn pickle(&mut self, what: &str) -> Result<Item, ImportError> {
        let mut stack: Vec<Slot> = Vec::new();
        loop {
            let at = self.pos;
            if at == self.bytes.len() {
                return Err(self.error(
                    at,
                    what,
                    "the file is truncated: it ends inside a pickle (no STOP opcode)",
                ));
            }
            let op = self.u8(what)?;
            let scalar = |value| Item {
                at,
                depth: 0,
                value,
            };
            let pushed = match op {
                // PROTO
                0x80 => {
                    let p = self.u8(what)?;
                    if !(2..=5).contains(&p) {
                        return Err(self.error(
                            at,
                            what,
                            format!("pickle protocol {p}; a legacy .pt file uses protocol 2"),
                        ));
                    }
                    None
                }
                // LONG1
                0x8a => {
                    let n = self.u8(what)? as usize;
                    Some(scalar(Value::Long(self.take(n, what)?.to_vec())))
                }
                b'K' => Some(scalar(Value::Int(i64::from(self.u8(what)?)))),
                b'M' => Some(scalar(Value::Int(i64::from(self.u16(what)?)))),
                b'J' => Some(scalar(Value::Int(i64::from(self.u32(what)? as i32)))),
                // BINUNICODE
                b'X' => {
                    let n = self.u32(what)? as usize;
                    let bytes = self.take(n, what)?;
                    let s = std::str::from_utf8(bytes)
                        .map_err(|_| self.error(at, what, "a str that is not UTF-8"))?;
                    Some(scalar(Value::Str(s.to_string())))
                }
                b'c' => {
                    let module = self.line(what)?;
                    let name = self.line(what)?;
                    Some(scalar(Value::Global(module, name)))
                }
                b'}' => Some(scalar(Value::Dict(Vec::new()))),
                b']' => Some(scalar(Value::List(Vec::new()))),
                b')' => Some(scalar(Value::Tuple(Vec::new()))),
                b'N' => Some(scalar(Value::None)),
                0x88 => Some(scalar(Value::Bool(true))),
                0x89 => Some(scalar(Value::Bool(false))),
                b'(' => {
                    stack.push(Slot::Mark(at));
                    None
                }
                b't' => {
                    let (start, items) = self.pop_mark(&mut stack, at, what, "TUPLE")?;
                    Some(self.container(start, what, Value::Tuple, items)?)
                }
                0x85..=0x87 => {
                    let n = usize::from(op - 0x84);
                    let mut items = Vec::with_capacity(n);
                    for _ in 0..n {
                        items.push(self.pop(&mut stack, at, what, "TUPLE1/2/3")?);
                    }
                    items.reverse();
                    let start = items.first().map_or(at, |i| i.at);
                    Some(self.container(start, what, Value::Tuple, items)?)
                }
                b'u' => {
                    let (_, items) = self.pop_mark(&mut stack, at, what, "SETITEMS")?;
                    if items.len() % 2 != 0 {
                        return Err(self.error(at, what, "SETITEMS with an odd number of values"));
                    }
                    let mut dict = self.pop(&mut stack, at, what, "SETITEMS")?;
                    let depth = items.iter().map(|i| i.depth + 1).max().unwrap_or(0);
                    let Value::Dict(entries) = &mut dict.value else {
                        return Err(self.error(
                            at,
                            what,
                            format!("SETITEMS on {}, not a dict", dict.kind()),
                        ));
                    };
                    let mut it = items.into_iter();
                    while let (Some(k), Some(v)) = (it.next(), it.next()) {
                        entries.push((k, v));
                    }
                    dict.depth = dict.depth.max(depth);
                    self.check_depth(&dict, what)?;
                    Some(dict)
                }
                b'a' => {
                    let item = self.pop(&mut stack, at, what, "APPEND")?;
                    let mut list = self.pop(&mut stack, at, what, "APPEND")?;
                    let depth = item.depth + 1;
                    let Value::List(items) = &mut list.value else {
                        return Err(self.error(
                            at,
                            what,
                            format!("APPEND to {}, not a list", list.kind()),
                        ));
                    };
                    items.push(item);
                    list.depth = list.depth.max(depth);
                    self.check_depth(&list, what)?;
                    Some(list)
                }
                // BINPUT: the memo is never read back (no BINGET in these
                // files), so only its operand is read.
                b'q' => {
                    self.u8(what)?;
                    if !matches!(stack.last(), Some(Slot::Item(_))) {
                        return Err(self.error(at, what, "BINPUT with no value on the stack"));
                    }
                    None
                }
                // BINPERSID
                b'Q' => {
                    let id = self.pop(&mut stack, at, what, "BINPERSID")?;
                    let item = Item {
                        at: id.at,
                        depth: id.depth + 1,
                        value: Value::Persistent(Box::new(id)),
                    };
                    self.check_depth(&item, what)?;
                    Some(item)
                }
                // REDUCE
                b'R' => {
                    let args = self.pop(&mut stack, at, what, "REDUCE")?;
                    let callable = self.pop(&mut stack, at, what, "REDUCE")?;
                    let Value::Tuple(args) = args.value else {
                        return Err(self.error(
                            at,
                            what,
                            format!("REDUCE with {} as arguments, not a tuple", args.kind()),
                        ));
                    };
                    let depth = args
                        .iter()
                        .map(|a| a.depth + 1)
                        .chain([callable.depth + 1])
                        .max()
                        .unwrap_or(1);
                    let item = Item {
                        at: callable.at,
                        depth,
                        value: Value::Call(Box::new(callable), args),
                    };
                    self.check_depth(&item, what)?;
                    Some(item)
                }
                b'.' => {
                    let mut items = stack.into_iter();
                    return match (items.next(), items.next()) {
                        (Some(Slot::Item(item)), None) => Ok(item),
                        (None, _) => Err(self.error(at, what, "STOP with an empty stack")),
                        _ => Err(self.error(
                            at,
                            what,
                            "STOP with more than one value (or a MARK) on the stack",
                        )),
                    };
                }
                other => {
                    let shown = if other.is_ascii_graphic() {
                        format!(" ('{}')", other as char)
                    } else {
                        String::new()
                    };
                    return Err(self.error(
                        at,
                        what,
                        format!(
                            "unknown pickle opcode 0x{other:02x}{shown}: not one a legacy .pt file of one tensor uses"
                        ),
                    ));
                }
            };
            if let Some(item) = pushed {
                stack.push(Slot::Item(item));
            }
        }
    }

    /// Pops a value for opcode `op`.
    fn pop(
        &self,
        stack: &mut Vec<Slot>,
        at: usize,
        what: &str,
        op: &str,
    ) -> Result<Item, ImportError> {
        match stack.pop() {
            Some(Slot::Item(item)) => Ok(item),
            Some(Slot::Mark(_)) => Err(self.error(at, what, format!("{op} finds a MARK"))),
            None => Err(self.error(at, what, format!("{op} with an empty stack"))),
        }
    }

    /// Pops the values down to the last MARK, in order, and the MARK's
    /// byte offset.
    fn pop_mark(
        &self,
        stack: &mut Vec<Slot>,
        at: usize,
        what: &str,
        op: &str,
    ) -> Result<(usize, Vec<Item>), ImportError> {
        let Some(mark) = stack.iter().rposition(|s| matches!(s, Slot::Mark(_))) else {
            return Err(self.error(at, what, format!("{op} without a MARK")));
        };
        let mut slots = stack.drain(mark..);
        let start = match slots.next() {
            Some(Slot::Mark(m)) => m,
            _ => at,
        };
        let items = slots
            .filter_map(|s| match s {
                Slot::Item(i) => Some(i),
                Slot::Mark(_) => None,
            })
            .collect();
        Ok((start, items))
    }

    /// A tuple (or list) of `items`, within the depth limit.
    fn container(
        &self,
        at: usize,
        what: &str,
        make: fn(Vec<Item>) -> Value,
        items: Vec<Item>,
    ) -> Result<Item, ImportError> {
        let depth = items.iter().map(|i| i.depth + 1).max().unwrap_or(0);
        let item = Item {
            at,
            depth,
            value: make(items),
        };
        self.check_depth(&item, what)?;
        Ok(item)
    }

    fn check_depth(&self, item: &Item, what: &str) -> Result<(), ImportError> {
        if item.depth > MAX_DEPTH {
            return Err(self.error(
                item.at,
                what,
                format!("containers nested deeper than {MAX_DEPTH} levels"),
            ));
        }
        Ok(())
    }
}

/// Reads a legacy `.pt` file's bytes; `file` names it in messages. Never
/// panics, whatever the bytes.
pub fn read_pt(bytes: &[u8], file: &Path) -> Result<PtTensor, ImportError> {
    let r = &mut Reader {
        bytes,
        pos: 0,
        file,
    };
    if bytes.is_empty() {
        return Err(ImportError::new(file, "the file is empty"));
    }
    if bytes.starts_with(b"PK\x03\x04") {
        return Err(r.error(
            0,
            "magic number",
            "a zip archive: PyTorch's newer format (torch.save since 1.6); only the legacy format is read (torch.save(..., _use_new_zipfile_serialization=False))",
        ));
    }
    let magic = r.pickle("magic number")?;
    if magic.value != Value::Long(MAGIC.to_vec()) {
        return Err(r.error(
            magic.at,
            "magic number",
            format!(
                "expected PyTorch's legacy magic number 0x1950a86a20f9469cfc6c, found {}",
                magic.kind()
            ),
        ));
    }
    let version = r.pickle("protocol version")?;
    if version.value != Value::Int(LEGACY_VERSION) {
        return Err(r.error(
            version.at,
            "protocol version",
            format!(
                "expected the legacy protocol version {LEGACY_VERSION}, found {}",
                version.kind()
            ),
        ));
    }
    let info = r.pickle("system info")?;
    check_sys_info(r, &info)?;
    let tensor = r.pickle("tensor")?;
    let storage = tensor_parts(r, &tensor)?;
    let keys = r.pickle("storage keys")?;
    match &keys.value {
        Value::List(items)
            if items.len() == 1 && items[0].value == Value::Str(storage.key.clone()) => {}
        _ => {
            return Err(r.error(
                keys.at,
                "storage keys",
                format!(
                    "expected the list [{:?}] (the tensor's one storage), found {}",
                    storage.key,
                    keys.kind()
                ),
            ))
        }
    }
    read_storage(r, storage)
}

/// Checks the system-info dict: little-endian, the legacy version.
fn check_sys_info(r: &Reader, info: &Item) -> Result<(), ImportError> {
    let Value::Dict(entries) = &info.value else {
        return Err(r.error(
            info.at,
            "system info",
            format!("expected a dict, found {}", info.kind()),
        ));
    };
    let get = |key: &str| {
        entries
            .iter()
            .find(|(k, _)| k.value == Value::Str(key.into()))
            .map(|(_, v)| v)
    };
    match get("little_endian") {
        Some(v) if v.value == Value::Bool(true) => {}
        Some(v) => {
            return Err(r.error(
                v.at,
                "system info: little_endian",
                format!(
                    "the file was written on a big-endian machine ({}); only little-endian files are read",
                    v.kind()
                ),
            ))
        }
        None => {
            return Err(r.error(
                info.at,
                "system info",
                "the dict has no \"little_endian\" entry",
            ))
        }
    }
    Ok(())
}

/// What the tensor's pickle says about its storage and layout.
struct StorageRef {
    key: String,
    count: u64,
    count_at: usize,
    shape: Vec<usize>,
    shape_at: usize,
}

/// A non-negative int that fits in usize, or an error about `field`.
fn size_of(r: &Reader, item: &Item, field: &str) -> Result<usize, ImportError> {
    match item.value {
        Value::Int(i) if i >= 0 => {
            usize::try_from(i).map_err(|_| r.error(item.at, field, format!("{i} is too large")))
        }
        _ => Err(r.error(
            item.at,
            field,
            format!("expected an int >= 0, found {}", item.kind()),
        )),
    }
}

/// The ints of a tuple (a size or a stride).
fn ints(r: &Reader, item: &Item, field: &str) -> Result<Vec<usize>, ImportError> {
    let Value::Tuple(items) = &item.value else {
        return Err(r.error(
            item.at,
            field,
            format!("expected a tuple of ints, found {}", item.kind()),
        ));
    };
    items.iter().map(|i| size_of(r, i, field)).collect()
}

/// Checks the tensor's pickle: `_rebuild_tensor_v2` of a DoubleStorage,
/// contiguous from its first element.
fn tensor_parts(r: &Reader, tensor: &Item) -> Result<StorageRef, ImportError> {
    let rebuild = Value::Global("torch._utils".into(), "_rebuild_tensor_v2".into());
    let args = match &tensor.value {
        Value::Call(f, args) if f.value == rebuild => Some(&args[..]),
        _ => None,
    };
    let Some([storage, offset, size, stride, requires_grad, hooks]) = args else {
        return Err(r.error(
            tensor.at,
            "tensor",
            format!(
                "expected a call of torch._utils._rebuild_tensor_v2 with 6 arguments (one saved tensor), found {}",
                tensor.kind()
            ),
        ));
    };
    // The persistent id: ("storage", torch.<Type>Storage, key, location, count, None).
    let id = match &storage.value {
        Value::Persistent(id) => match &id.value {
            Value::Tuple(parts) if parts.len() == 6 => parts,
            _ => {
                return Err(r.error(
                    id.at,
                    "storage",
                    format!(
                        "expected the persistent id (\"storage\", type, key, location, size, None), found {}",
                        id.kind()
                    ),
                ))
            }
        },
        _ => {
            return Err(r.error(
                storage.at,
                "storage",
                format!("expected a persistent id, found {}", storage.kind()),
            ))
        }
    };
    if id[0].value != Value::Str("storage".into()) {
        return Err(r.error(
            id[0].at,
            "storage",
            format!("expected the str \"storage\", found {}", id[0].kind()),
        ));
    }
    match &id[1].value {
        Value::Global(m, n) if m == "torch" && n == "DoubleStorage" => {}
        Value::Global(m, n) => {
            let what = match n.as_str() {
                "FloatStorage" => " (float32 values)",
                "HalfStorage" => " (float16 values)",
                "BFloat16Storage" => " (bfloat16 values)",
                "LongStorage" | "IntStorage" | "ShortStorage" | "CharStorage" | "ByteStorage" => {
                    " (integers)"
                }
                _ => "",
            };
            return Err(r.error(
                id[1].at,
                "storage type",
                format!("the tensor's storage is {m}.{n}{what}; expected torch.DoubleStorage (float64 values)"),
            ));
        }
        _ => {
            return Err(r.error(
                id[1].at,
                "storage type",
                format!("expected a storage type, found {}", id[1].kind()),
            ))
        }
    }
    let Value::Str(key) = &id[2].value else {
        return Err(r.error(
            id[2].at,
            "storage key",
            format!("expected a str, found {}", id[2].kind()),
        ));
    };
    if !matches!(id[3].value, Value::Str(_)) {
        return Err(r.error(
            id[3].at,
            "storage location",
            format!("expected a str such as \"cpu\", found {}", id[3].kind()),
        ));
    }
    let count = size_of(r, &id[4], "storage size")? as u64;
    if id[5].value != Value::None {
        return Err(r.error(
            id[5].at,
            "storage view",
            format!(
                "the storage is a view of another ({}); only a whole storage is read",
                id[5].kind()
            ),
        ));
    }
    let start = size_of(r, offset, "storage offset")?;
    if start != 0 {
        return Err(r.error(
            offset.at,
            "storage offset",
            format!("the tensor starts at element {start} of its storage; only a tensor from the storage's first element is read"),
        ));
    }
    let shape = ints(r, size, "tensor size")?;
    let strides = ints(r, stride, "tensor stride")?;
    if strides.len() != shape.len() {
        return Err(r.error(
            stride.at,
            "tensor stride",
            format!("{} strides for {} dimensions", strides.len(), shape.len()),
        ));
    }
    // Contiguous (row-major): each stride is the product of the sizes
    // after it; a dimension of size 1 may have any stride.
    let mut inner: usize = 1;
    for d in (0..shape.len()).rev() {
        if shape[d] != 1 && strides[d] != inner {
            return Err(r.error(
                stride.at,
                "tensor stride",
                format!(
                    "strides {strides:?} for size {shape:?} are not those of a contiguous tensor ({} expected in dimension {d})",
                    inner
                ),
            ));
        }
        inner = inner
            .checked_mul(shape[d])
            .ok_or_else(|| r.error(size.at, "tensor size", format!("size {shape:?} overflows")))?;
    }
    if inner as u64 != count {
        return Err(r.error(
            id[4].at,
            "storage size",
            format!(
                "the storage holds {count} elements, the tensor's size {shape:?} needs {inner}"
            ),
        ));
    }
    if !matches!(requires_grad.value, Value::Bool(_)) {
        return Err(r.error(
            requires_grad.at,
            "requires_grad",
            format!("expected True or False, found {}", requires_grad.kind()),
        ));
    }
    let ordered_dict = Value::Global("collections".into(), "OrderedDict".into());
    match &hooks.value {
        Value::Call(f, a) if f.value == ordered_dict && a.is_empty() => {}
        _ => {
            return Err(r.error(
                hooks.at,
                "backward hooks",
                format!("expected an empty OrderedDict(), found {}", hooks.kind()),
            ))
        }
    }
    Ok(StorageRef {
        key: key.clone(),
        count,
        count_at: id[4].at,
        shape,
        shape_at: size.at,
    })
}

/// Reads the raw storage after the pickles: an i64 element count, then the
/// elements, and nothing after them.
fn read_storage(r: &mut Reader, s: StorageRef) -> Result<PtTensor, ImportError> {
    let at = r.pos;
    let head = r.take(8, "storage element count")?;
    let n = i64::from_le_bytes(head.try_into().unwrap_or([0; 8]));
    if u64::try_from(n).ok() != Some(s.count) {
        return Err(r.error(
            at,
            "storage element count",
            format!(
                "the raw storage says {n} elements, the pickle (byte {}) says {}",
                s.count_at, s.count
            ),
        ));
    }
    let values_at = r.pos;
    let left = r.bytes.len() - values_at;
    let needed = usize::try_from(s.count)
        .ok()
        .and_then(|c| c.checked_mul(8))
        .filter(|&b| b <= left)
        .ok_or_else(|| {
            r.error(
                values_at,
                "storage",
                format!(
                    "the file is truncated: the storage's {} float64 values need {} bytes, the file ends {left} bytes later (at byte {})",
                    s.count,
                    s.count.saturating_mul(8),
                    r.bytes.len()
                ),
            )
        })?;
    let data = r.take(needed, "storage")?;
    let values: Vec<f64> = data
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
        .collect();
    if r.pos != r.bytes.len() {
        return Err(r.error(
            r.pos,
            "end of file",
            format!(
                "{} bytes after the storage's end; a legacy .pt file of one tensor ends there",
                r.bytes.len() - r.pos
            ),
        ));
    }
    Ok(PtTensor {
        shape: s.shape,
        values,
        shape_at: s.shape_at,
        values_at,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(bytes: &[u8]) -> Result<PtTensor, String> {
        read_pt(bytes, Path::new("t.pt")).map_err(|e| e.to_string())
    }

    /// A pickle of the given opcodes after PROTO 2.
    fn pickle(body: &[u8]) -> Vec<u8> {
        let mut p = vec![0x80, 2];
        p.extend_from_slice(body);
        p
    }

    #[test]
    fn empty_zip_and_foreign_files_are_named() {
        assert_eq!(read(b"").unwrap_err(), "t.pt: the file is empty");
        assert!(read(b"PK\x03\x04rest")
            .unwrap_err()
            .starts_with("t.pt: byte 0 (magic number): a zip archive"));
        assert_eq!(
            read(&pickle(b"K\x07.")).unwrap_err(),
            "t.pt: byte 2 (magic number): expected PyTorch's legacy magic number 0x1950a86a20f9469cfc6c, found the int 7"
        );
        assert_eq!(
            read(b"hello").unwrap_err(),
            "t.pt: byte 0 (magic number): unknown pickle opcode 0x68 ('h'): not one a legacy .pt file of one tensor uses"
        );
    }

    #[test]
    fn stack_machine_errors_are_located() {
        for (body, want) in [
            (&b"t"[..], "byte 2 (magic number): TUPLE without a MARK"),
            (b"R", "byte 2 (magic number): REDUCE with an empty stack"),
            (b"K\x01K\x02.", "byte 6 (magic number): STOP with more than one value"),
            (b".", "byte 2 (magic number): STOP with an empty stack"),
            (b"K\x01", "byte 4 (magic number): the file is truncated: it ends inside a pickle"),
            (b"X\xff\xff\xff\xff", "byte 7 (magic number): the file is truncated: magic number needs 4294967295 bytes, the file ends 0 bytes later (at byte 7)"),
            (b")R", "byte 3 (magic number): REDUCE with an empty stack"),
            (b"K\x01K\x02R", "byte 6 (magic number): REDUCE with the int 2 as arguments, not a tuple"),
            (b"cmod", "byte 3 (magic number): the file is truncated: it ends inside a global's name (at byte 6)"),
            (b"q\x00", "byte 2 (magic number): BINPUT with no value on the stack"),
            (b"K\x01K\x02u", "byte 6 (magic number): SETITEMS without a MARK"),
            (b"}(K\x01u", "byte 6 (magic number): SETITEMS with an odd number of values"),
            (b"K\x01K\x02a", "byte 6 (magic number): APPEND to the int 1, not a list"),
        ] {
            let e = read(&pickle(body)).unwrap_err();
            assert!(e.starts_with(&format!("t.pt: {want}")), "{body:?}: {e}");
        }
        // Deep nesting is refused before it can exhaust the stack.
        let mut deep = b"K\x01".to_vec();
        deep.extend(std::iter::repeat_n(0x85, 100));
        deep.push(b'.');
        let e = read(&pickle(&deep)).unwrap_err();
        assert!(e.contains("containers nested deeper than 8 levels"), "{e}");
        let e = read(&[0x80, 9]).unwrap_err();
        assert!(e.contains("pickle protocol 9"), "{e}");
    }
}
