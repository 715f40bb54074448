//! ASCII PLY bodies: parsing into little-endian records, and writing records back as text.
//!
//! Our own strict parser rather than `ply-rs-bw`: that crate reports a line but not which element
//! failed, puts the offending line and a `Debug` dump into a multi-line message, silently accepts
//! extra values on a line and data after the last element, and stores each record in its own hash
//! map (an allocation per vertex). Here every record is one line with exactly the values its
//! properties call for, and the result is the same little-endian records the binary path decodes,
//! so positions, faces and all their checks are shared with it.

use std::io::{self, Write};

use super::header::{Element, Kind, Property, Scalar, walk_record};
use crate::io::{F32, F64, show, tokens};

/// Parses the body that starts on line `first_line` into each element's little-endian records.
pub(crate) fn parse_body(
    body: &[u8],
    first_line: usize,
    elements: &[Element],
) -> Result<Vec<Vec<u8>>, String> {
    // The empty piece after a final newline is not a line.
    let real =
        crate::io::lines(body).count() - usize::from(body.is_empty() || body.ends_with(b"\n"));
    let mut lines = crate::io::lines(body)
        .take(real)
        .map(|(n, line)| (n + first_line - 1, line));
    let mut out = Vec::with_capacity(elements.len());
    for el in elements {
        // Grown as lines are parsed, never reserved from the header's count: a count the file
        // cannot back fails at the file's real end, after reading no more than the file.
        let mut records = Vec::new();
        for i in 0..el.count {
            let Some((n, line)) = lines.next() else {
                let what = format!(
                    "file ends early (the header declares {} {} records)",
                    el.count, el.name
                );
                // The record would be on the line after the last one.
                return Err(format!(
                    "{} {i} (line {}): {what}",
                    el.name,
                    first_line + real
                ));
            };
            parse_record(line, &el.props, &mut records)
                .map_err(|what| format!("{} {i} (line {n}): {what}", el.name))?;
        }
        out.push(records);
    }
    if let Some((n, line)) = lines.find(|(_, line)| tokens(line).next().is_some()) {
        let first = tokens(line).next().unwrap_or_default();
        return Err(format!(
            "line {n}: unexpected data after the last element: {}",
            show(first)
        ));
    }
    Ok(out)
}

/// Appends one line's record to `records`.
fn parse_record(line: &[u8], props: &[Property], records: &mut Vec<u8>) -> Result<(), String> {
    let mut values = tokens(line);
    let mut next = |p: &Property| {
        values
            .next()
            .ok_or_else(|| format!("too few values: '{}' is missing", p.name))
    };
    for p in props {
        match p.kind {
            Kind::Scalar(t) => {
                push(records, t, next(p)?, p)?;
            }
            Kind::List(c, t) => {
                let n = push(records, c, next(p)?, p)?;
                if n < 0.0 {
                    return Err(format!("negative list count {n} for '{}'", p.name));
                }
                for _ in 0..n as usize {
                    push(records, t, next(p)?, p)?;
                }
            }
        }
    }
    match values.next() {
        Some(extra) => Err(format!(
            "unexpected value {} after the last property",
            show(extra)
        )),
        None => Ok(()),
    }
}

/// Encodes one token as type `t`, returning its value.
fn push(records: &mut Vec<u8>, t: Scalar, token: &[u8], p: &Property) -> Result<f64, String> {
    let text = std::str::from_utf8(token).unwrap_or_default();
    let value = match (t, t.int_range()) {
        (Scalar::F32, _) => text.parse::<f32>().map(f64::from).ok(),
        (_, None) => text.parse::<f64>().ok(),
        (_, Some((lo, hi))) => {
            let v = crate::io::integer(token)
                .map_err(|e| format!("{e} ('{}' is {})", p.name, t.name()))?;
            if !(lo..=hi).contains(&v) {
                return Err(format!(
                    "value {v} does not fit '{}' ({})",
                    p.name,
                    t.name()
                ));
            }
            Some(v as f64)
        }
    };
    let value = value.ok_or_else(|| {
        format!(
            "{} is not a number ('{}' is {})",
            show(token),
            p.name,
            t.name()
        )
    })?;
    // A finite number too large for the type would be carried as infinity; an infinity (or a
    // NaN) written as such is the file's own value.
    let spelled_infinite = text
        .trim_start_matches(['+', '-'])
        .to_ascii_lowercase()
        .starts_with("inf");
    if value.is_infinite() && !spelled_infinite {
        return Err(format!(
            "value {} does not fit '{}' ({})",
            show(token),
            p.name,
            t.name()
        ));
    }
    let at = records.len();
    records.resize(at + t.size(), 0);
    t.put(value, &mut records[at..]);
    Ok(value)
}

/// Writes little-endian records as ASCII lines, floats in their shortest exact form.
pub(crate) fn write_records(
    out: &mut impl Write,
    props: &[Property],
    records: &[u8],
) -> io::Result<()> {
    let mut fields = Vec::new();
    let mut pos = 0;
    while pos < records.len() {
        let end = walk_record(records, pos, props, false, &mut fields)
            .map_err(|_| io::Error::other("PLY records are corrupt"))?;
        for (k, (p, f)) in props.iter().zip(&fields).enumerate() {
            if k > 0 {
                out.write_all(b" ")?;
            }
            match p.kind {
                Kind::Scalar(t) => write_value(out, t, &records[f.at..])?,
                Kind::List(c, t) => {
                    write!(out, "{}", f.n)?;
                    for j in 0..f.n {
                        out.write_all(b" ")?;
                        write_value(out, t, &records[f.at + c.size() + j * t.size()..])?;
                    }
                }
            }
        }
        out.write_all(b"\n")?;
        pos = end;
    }
    Ok(())
}

fn write_value(out: &mut impl Write, t: Scalar, bytes: &[u8]) -> io::Result<()> {
    let v = t.get(bytes).unwrap_or_default();
    match t {
        Scalar::F32 => write!(out, "{}", F32(v as f32)),
        Scalar::F64 => write!(out, "{}", F64(v)),
        _ => write!(out, "{}", v as i64),
    }
}
