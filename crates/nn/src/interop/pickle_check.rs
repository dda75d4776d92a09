//! What a PyTorch checkpoint's pickle may ask for, checked before anything
//! reads it.
//!
//! A `.pth` file is a pickle program: unpickled by Python it may call any
//! importable function (`os.system` included). pgrf never runs it (burn's
//! reader parses the opcodes into data), and on top of that it accepts only
//! the subset a state dict needs: tensors rebuilt from storages, ordered
//! dicts, plain numbers and strings. Every global the program names must be
//! on the allowlist (`ALLOWED`); opcodes that build arbitrary objects (INST, OBJ, NEWOBJ,
//! the extension registry) are refused, and a STACK_GLOBAL whose module and
//! name this walk cannot read off the two strings just pushed is refused
//! rather than guessed. The walk follows pickletools' opcode table
//! (protocols 0-5) and never allocates more than the opcodes it reads.

/// The globals a state dict's pickle needs.
const ALLOWED: &[(&str, &str)] = &[
    ("collections", "OrderedDict"),
    ("torch._utils", "_rebuild_tensor_v2"),
    ("torch._utils", "_rebuild_parameter"),
    ("torch", "FloatStorage"),
    ("torch", "DoubleStorage"),
    ("torch", "HalfStorage"),
    ("torch", "BFloat16Storage"),
    ("torch", "LongStorage"),
    ("torch", "IntStorage"),
    ("torch", "ShortStorage"),
    ("torch", "CharStorage"),
    ("torch", "ByteStorage"),
    ("torch", "BoolStorage"),
];

/// How a pickle opcode's argument is laid out.
enum Arg {
    None,
    Fixed(usize),
    /// A little-endian length of this many bytes, then that many bytes.
    Counted(usize),
    /// One newline-terminated line.
    Line,
    /// Two newline-terminated lines (GLOBAL, INST).
    TwoLines,
}

fn arg_of(op: u8) -> Option<Arg> {
    use Arg::*;
    Some(match op {
        b'(' | b'.' | b'0' | b'1' | b'2' | b'N' | b'a' | b'b' | b'd' | b'}' | b'e' | b'l'
        | b']' | b'o' | b'R' | b's' | b't' | b')' | b'u' | b'Q' => None,
        0x88 | 0x89 | 0x85 | 0x86 | 0x87 | 0x81 | 0x92 | 0x93 | 0x94 | 0x8f | 0x90 | 0x91
        | 0x97 | 0x98 => None,
        b'K' | b'h' | b'q' | 0x80 | 0x82 => Fixed(1),
        b'M' | 0x83 => Fixed(2),
        b'J' | b'j' | b'r' | 0x84 => Fixed(4),
        b'G' | 0x95 => Fixed(8),
        b'U' | 0x8c | b'C' | 0x8a => Counted(1),
        b'T' | b'X' | b'B' | 0x8b => Counted(4),
        0x8d | 0x8e | 0x96 => Counted(8),
        b'I' | b'L' | b'F' | b'S' | b'V' | b'P' | b'g' | b'p' => Line,
        b'c' | b'i' => TwoLines,
        _ => return Option::None,
    })
}

/// Check the pickle program(s) at the start of `bytes`: `programs` of them
/// one after the other (1 for a zip checkpoint's data.pkl; a legacy
/// checkpoint starts with 4: magic number, protocol, system info, data).
/// Returns the number of bytes they take, or why the file is refused.
// String because a refused pickle can only be reported, never mended: the
// reader (`torch_file`) puts the sentence, with the byte it names, into its
// own error about the file.
pub fn check(bytes: &[u8], programs: usize) -> Result<usize, String> {
    let mut at = 0usize;
    for _ in 0..programs {
        at += check_one(&bytes[at..])
            .map_err(|(off, why)| format!("pickle byte {}: {why}", at + off))?;
    }
    Ok(at)
}

/// One program up to its STOP; (offset, reason) on refusal.
fn check_one(bytes: &[u8]) -> Result<usize, (usize, String)> {
    let mut at = 0usize;
    // The two values most recently pushed, when they were strings (what a
    // STACK_GLOBAL takes), and the memo's strings.
    let mut top: [Option<String>; 2] = [None, None];
    let mut memo: std::collections::HashMap<u64, String> = std::collections::HashMap::new();
    let mut memo_next: u64 = 0;
    loop {
        let start = at;
        let &op = bytes.get(at).ok_or_else(|| truncated(at))?;
        at += 1;
        let Some(kind) = arg_of(op) else {
            return Err((start, format!("unknown pickle opcode 0x{op:02x}")));
        };
        let (arg, next) = read_arg(bytes, at, kind)?;
        at = next;
        let text = |a: &[u8]| String::from_utf8_lossy(a).into_owned();
        let mut pushed: Option<Option<String>> = Some(None);
        match op {
            b'.' => return Ok(at),
            b'c' => {
                let s = text(arg);
                let (module, name) = s.split_once('\n').unwrap_or((&s, ""));
                if let Some(why) = refused_call(module, name) {
                    return Err((start, why));
                }
            }
            0x93 => {
                let (Some(module), Some(name)) = (&top[0], &top[1]) else {
                    return Err((
                        start,
                        "a STACK_GLOBAL whose module and name are not the two strings pushed just before it".into(),
                    ));
                };
                if let Some(why) = refused_call(module, name) {
                    return Err((start, why));
                }
            }
            b'i' | b'o' | 0x81 | 0x92 | 0x82 | 0x83 | 0x84 => {
                return Err((
                    start,
                    format!(
                        "opcode 0x{op:02x} builds an arbitrary Python object; a state dict of tensors never needs it"
                    ),
                ));
            }
            0x8c | b'X' | 0x8d => pushed = Some(Some(text(arg))),
            b'V' => pushed = Some(Some(text(arg))),
            // Memo stores keep the stack as it is.
            0x94 => {
                if let Some(s) = &top[1] {
                    memo.insert(memo_next, s.clone());
                }
                memo_next += 1;
                pushed = None;
            }
            b'q' | b'r' | b'p' => {
                if let Some(s) = &top[1] {
                    memo.insert(memo_index(op, arg), s.clone());
                }
                pushed = None;
            }
            b'h' | b'j' | b'g' => pushed = Some(memo.get(&memo_index(op, arg)).cloned()),
            0x80 | 0x95 => pushed = None,
            _ => {}
        }
        if let Some(p) = pushed {
            top = [top[1].take(), p];
        }
    }
}

/// The refusal of a pickle that ends at `at` before its STOP.
fn truncated(at: usize) -> (usize, String) {
    (
        at,
        "the pickle ends before its STOP opcode (truncated?)".to_string(),
    )
}

/// The argument of an opcode of argument kind `kind` starting at `at`, and
/// where the next opcode starts; (offset, reason) when the pickle ends
/// first.
fn read_arg(bytes: &[u8], at: usize, kind: Arg) -> Result<(&[u8], usize), (usize, String)> {
    let mut at = at;
    let arg: &[u8] = match kind {
        Arg::None => &[],
        Arg::Fixed(n) => {
            let a = bytes.get(at..at + n).ok_or_else(|| truncated(at))?;
            at += n;
            a
        }
        Arg::Counted(n) => {
            let len = bytes.get(at..at + n).ok_or_else(|| truncated(at))?;
            let mut v = [0u8; 8];
            v[..n].copy_from_slice(len);
            let len = u64::from_le_bytes(v);
            at += n;
            let end = (at as u64)
                .checked_add(len)
                .filter(|&e| e <= bytes.len() as u64)
                .ok_or_else(|| truncated(at))? as usize;
            let a = &bytes[at..end];
            at = end;
            a
        }
        Arg::Line => {
            let n = line_end(bytes, at).ok_or_else(|| truncated(at))?;
            let a = &bytes[at..n];
            at = n + 1;
            a
        }
        Arg::TwoLines => {
            let m = line_end(bytes, at).ok_or_else(|| truncated(at))?;
            let n = line_end(bytes, m + 1).ok_or_else(|| truncated(m + 1))?;
            let a = &bytes[at..n];
            at = n + 1;
            a
        }
    };
    Ok((arg, at))
}

/// The memo index in the argument of a PUT/GET family opcode `op`: one
/// byte (BINPUT, BINGET), four little-endian bytes (LONG_BINPUT,
/// LONG_BINGET) or a decimal line (PUT, GET; unreadable: an index no
/// string has).
fn memo_index(op: u8, arg: &[u8]) -> u64 {
    match op {
        b'q' | b'h' => arg[0] as u64,
        b'r' | b'j' => u32::from_le_bytes(arg.try_into().expect("4 bytes")) as u64,
        _ => String::from_utf8_lossy(arg)
            .trim()
            .parse()
            .unwrap_or(u64::MAX),
    }
}

fn line_end(bytes: &[u8], from: usize) -> Option<usize> {
    bytes
        .get(from..)?
        .iter()
        .position(|&b| b == b'\n')
        .map(|i| from + i)
}

/// Why the pickle may not call `module.name`; None when a state dict of
/// tensors needs it.
fn refused_call(module: &str, name: &str) -> Option<String> {
    (!ALLOWED.contains(&(module, name))).then(|| {
        format!(
            "the pickle calls {module}.{name}, which a state dict of tensors does not need (pgrf reads only tensors, ordered dicts, numbers and strings)"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// GLOBAL os.system with a REDUCE: refused by name.
    #[test]
    fn a_global_outside_the_list_is_refused() {
        let p = b"\x80\x02cos\nsystem\nX\x04\x00\x00\x00echo\x85R.";
        let e = check(p, 1).unwrap_err();
        assert!(e.contains("os.system"), "{e}");
    }

    /// Protocol 4's STACK_GLOBAL of memoized strings: allowed for
    /// collections.OrderedDict, refused for builtins.eval, refused when the
    /// strings are not what was just pushed.
    #[test]
    fn stack_globals_are_read_off_the_pushed_strings() {
        let ok = b"\x80\x04\x8c\x0bcollections\x94\x8c\x0bOrderedDict\x94\x93\x94)R\x94.";
        assert_eq!(check(ok, 1).unwrap(), ok.len());
        let bad = b"\x80\x04\x8c\x08builtins\x94\x8c\x04eval\x94\x93\x94.";
        assert!(check(bad, 1).unwrap_err().contains("builtins.eval"));
        let hidden = b"\x80\x04\x8c\x08builtins\x94K\x01\x93.";
        assert!(check(hidden, 1).unwrap_err().contains("STACK_GLOBAL"));
        // The same strings fetched back from the memo are recognised.
        let memo =
            b"\x80\x04\x8c\x0bcollections\x94\x8c\x0bOrderedDict\x94\x93\x94)Rh\x00h\x01\x93.";
        assert_eq!(check(memo, 1).unwrap(), memo.len());
    }

    #[test]
    fn truncation_and_object_builders_are_refused() {
        assert!(check(b"\x80\x02}q\x00", 1)
            .unwrap_err()
            .contains("truncated"));
        assert!(check(b"\x80\x02X\xff\xff\xff\x7fab", 1)
            .unwrap_err()
            .contains("truncated"));
        assert!(check(b"\x80\x02(\x81.", 1)
            .unwrap_err()
            .contains("arbitrary"));
        assert!(check(b"\xff", 1)
            .unwrap_err()
            .contains("unknown pickle opcode 0xff"));
    }
}
