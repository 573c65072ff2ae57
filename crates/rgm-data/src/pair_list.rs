//! Lists of pairs of cloud files, as `rgm register --pairs LIST` reads them: CSV whose header
//! names the columns `source` and `target` (in any order; other columns are ignored, `#` lines
//! are comments, a field in double quotes may hold commas), or JSON: a list of
//! `{"source": FILE, "target": FILE}`, or an object whose `"pairs"` is one (the `pairs.json` of
//! `rgm pairs`). Told apart by the first character; a byte-order mark is skipped.

use std::path::Path;

use serde_json::Value;

/// One pair of a list: its files as the list spells them, and where it is listed (`FILE:LINE`
/// or `FILE entry N`, for messages).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ListedPair {
    pub source: String,
    pub target: String,
    pub place: String,
}

/// Why a list is not one: the message names the file, the line and the value.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("{0}")]
pub struct PairListError(pub String);

/// The pairs of the list `text`, read from `path` (named in messages), in their order.
pub fn parse(path: &Path, text: &str) -> Result<Vec<ListedPair>, PairListError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    if text.trim_start().starts_with(['[', '{']) {
        json(path, text)
    } else {
        csv(path, text)
    }
}

/// The pairs of a CSV list.
fn csv(path: &Path, text: &str) -> Result<Vec<ListedPair>, PairListError> {
    let mut rows = text
        .lines()
        .enumerate()
        .map(|(i, line)| (i + 1, line))
        .filter(|(_, line)| !line.trim().is_empty() && !line.trim_start().starts_with('#'));
    let at = |n: usize| format!("{}:{n}", path.display());
    let Some((n, header)) = rows.next() else {
        return Err(PairListError(format!(
            "{}: no header line `source,target`",
            path.display()
        )));
    };
    let names =
        csv_fields(header).map_err(|why| PairListError(format!("{}: {why}: `{header}`", at(n))))?;
    let column = |name: &str| names.iter().position(|h| h.eq_ignore_ascii_case(name));
    let (Some(s), Some(t)) = (column("source"), column("target")) else {
        return Err(PairListError(format!(
            "{}: the header must name the columns `source` and `target`: `{header}`",
            at(n)
        )));
    };
    let mut pairs = Vec::new();
    for (n, line) in rows {
        let fields =
            csv_fields(line).map_err(|why| PairListError(format!("{}: {why}: `{line}`", at(n))))?;
        let get = |k: usize, name: &str| match fields.get(k) {
            Some(f) if !f.is_empty() => Ok(f.clone()),
            _ => Err(PairListError(format!(
                "{}: no {name} file (column {}): `{line}`",
                at(n),
                k + 1
            ))),
        };
        pairs.push(ListedPair {
            source: get(s, "source")?,
            target: get(t, "target")?,
            place: at(n),
        });
    }
    Ok(pairs)
}

/// The comma-separated fields of a CSV line, trimmed; a field in double quotes may hold commas,
/// and `""` inside it is one quote.
fn csv_fields(line: &str) -> Result<Vec<String>, &'static str> {
    let mut fields = Vec::new();
    let mut chars = line.chars().peekable();
    loop {
        while chars.peek().is_some_and(|c| c.is_whitespace()) {
            chars.next();
        }
        let mut field = String::new();
        if chars.peek() == Some(&'"') {
            chars.next();
            loop {
                match chars.next() {
                    Some('"') if chars.peek() == Some(&'"') => {
                        chars.next();
                        field.push('"');
                    }
                    Some('"') => break,
                    Some(c) => field.push(c),
                    None => return Err("a quoted field has no closing quote"),
                }
            }
            while chars.peek().is_some_and(|c| c.is_whitespace()) {
                chars.next();
            }
            if !matches!(chars.peek(), None | Some(',')) {
                return Err("text after a quoted field");
            }
        } else {
            while let Some(&c) = chars.peek() {
                if c == ',' {
                    break;
                }
                field.push(c);
                chars.next();
            }
            field = field.trim_end().to_string();
        }
        fields.push(field);
        if chars.next().is_none() {
            return Ok(fields);
        }
    }
}

/// The pairs of a JSON list.
fn json(path: &Path, text: &str) -> Result<Vec<ListedPair>, PairListError> {
    let value: Value = serde_json::from_str(text)
        .map_err(|e| PairListError(format!("{}: not valid JSON: {e}", path.display())))?;
    let entries = value
        .as_array()
        .or_else(|| value.get("pairs").and_then(Value::as_array))
        .ok_or_else(|| {
            PairListError(format!(
                "{}: a JSON list of pairs is a list of {{\"source\": FILE, \"target\": FILE}}, \
                 or an object whose \"pairs\" is one",
                path.display()
            ))
        })?;
    entries
        .iter()
        .enumerate()
        .map(|(i, entry)| {
            let place = format!("{} entry {}", path.display(), i + 1);
            let get = |name: &str| match entry.get(name) {
                Some(Value::String(file)) if !file.is_empty() => Ok(file.clone()),
                _ => Err(PairListError(format!(
                    "{place}: no \"{name}\" file name: `{}`",
                    shortened(&entry.to_string())
                ))),
            };
            Ok(ListedPair {
                source: get("source")?,
                target: get("target")?,
                place,
            })
        })
        .collect()
}

/// `text` cut to its first 120 characters, for messages.
pub fn shortened(text: &str) -> String {
    match text.char_indices().nth(120) {
        Some((end, _)) => format!("{}…", &text[..end]),
        None => text.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_fields_split_on_commas_outside_quotes() {
        assert_eq!(csv_fields(" a.ply , b.ply").unwrap(), ["a.ply", "b.ply"]);
        assert_eq!(
            csv_fields(r#""x, y.ply", "say ""hi"".ply",,z"#).unwrap(),
            ["x, y.ply", r#"say "hi".ply"#, "", "z"]
        );
        assert_eq!(
            csv_fields(r#""open"#),
            Err("a quoted field has no closing quote")
        );
        assert_eq!(csv_fields(r#""a"b,c"#), Err("text after a quoted field"));
    }

    #[test]
    fn both_kinds_of_list_give_the_pairs_and_name_a_bad_row() {
        let path = Path::new("list");
        let csv_pairs =
            parse(path, "\u{feff}# made by hand\ntarget,source\nb.ply,a.ply\n").unwrap();
        assert_eq!(
            csv_pairs,
            [ListedPair {
                source: "a.ply".into(),
                target: "b.ply".into(),
                place: "list:3".into()
            }]
        );
        let json_pairs = parse(
            path,
            r#"{"pairs": [{"source": "a.ply", "target": "b.ply"}]}"#,
        );
        assert_eq!(json_pairs.unwrap()[0].place, "list entry 1");
        assert_eq!(
            parse(path, "source,target\na.ply,\n").unwrap_err().0,
            "list:2: no target file (column 2): `a.ply,`"
        );
    }
}
