//! Writing a scene file over the text it was read from, keeping that text's comments, order
//! and spelling wherever the value is unchanged (`toml_edit` keeps them; `toml` would drop
//! them).

use toml_edit::{ArrayOfTables, DocumentMut, Item, Table, Value};

use super::SceneFile;

/// Why a scene file could not be written over its original text.
#[derive(Debug, thiserror::Error)]
pub enum EditError {
    /// The original text is not TOML any more.
    #[error("the original scene file is not TOML: {0}")]
    Original(#[source] toml_edit::TomlError),
    /// serde could not write a value as TOML.
    #[error(transparent)]
    Write(#[from] toml::ser::Error),
    /// What serde wrote did not read back as TOML.
    #[error("the written scene file does not read back: {0}")]
    Written(#[source] toml_edit::TomlError),
}

impl SceneFile {
    /// The file as TOML text written over `original`, the text it was read from: keys whose
    /// value is unchanged keep their text as it was (`1` stays `1`, not `1.0`), changed values
    /// keep the comments around them, keys the file no longer has go with their comments, and
    /// new keys and tables are added after the rest. Arrays of tables (`[[mesh]]`,
    /// `[[measurement]]`) are matched element by element, in order.
    ///
    /// # Errors
    ///
    /// When `original` is not TOML, or this file cannot be written as TOML.
    pub fn to_toml_over(&self, original: &str) -> Result<String, EditError> {
        let mut doc: DocumentMut = original.parse().map_err(EditError::Original)?;
        let new: DocumentMut = self.to_toml()?.parse().map_err(EditError::Written)?;
        merge_table(doc.as_table_mut(), new.as_table().clone());
        Ok(doc.to_string())
    }
}

/// Makes `old` hold `new`'s keys and values, keeping `old`'s text where it is unchanged.
fn merge_table(old: &mut Table, new: Table) {
    let gone: Vec<String> = old
        .iter()
        .map(|(k, _)| k.to_owned())
        .filter(|k| !new.contains_key(k))
        .collect();
    for k in gone {
        old.remove(&k);
    }
    for (key, item) in new {
        match old.get_mut(&key) {
            Some(slot) => merge_item(slot, item),
            // A table of defaults only (`[lights]`, `[volume.transform]`) means nothing the
            // original did not say.
            None if holds_nothing(&item) => {}
            None => {
                old.insert(&key, item);
            }
        }
    }
}

/// Whether `item` is a table with nothing but tables with nothing in them.
fn holds_nothing(item: &Item) -> bool {
    match item {
        Item::Table(t) => t.iter().all(|(_, i)| holds_nothing(i)),
        Item::Value(Value::InlineTable(t)) => t.is_empty(),
        _ => false,
    }
}

/// Makes `old` hold `new`, keeping `old`'s text where it is unchanged and its decoration
/// (comments, spacing) where it changed.
fn merge_item(old: &mut Item, new: Item) {
    match (old, new) {
        (Item::Table(o), Item::Table(n)) => merge_table(o, n),
        (Item::Table(o), Item::Value(Value::InlineTable(n))) => merge_table(o, n.into_table()),
        (Item::ArrayOfTables(o), Item::ArrayOfTables(n)) => merge_array(o, n),
        (Item::Value(o), Item::Value(n)) => merge_value(o, n),
        (Item::Value(o), Item::Table(n)) if o.is_inline_table() => {
            merge_value(o, Value::InlineTable(n.into_inline_table()));
        }
        (old, new) => *old = new,
    }
}

/// Keeps `old` where it means `new`; else `new` in its place, with `old`'s decoration.
fn merge_value(old: &mut Value, mut new: Value) {
    if same(old, &new) {
        return;
    }
    if let (Value::InlineTable(o), Value::InlineTable(n)) = (&mut *old, &new) {
        // Inline tables change key by key, as tables do.
        let mut table = o.clone().into_table();
        merge_table(&mut table, n.clone().into_table());
        let mut inline = table.into_inline_table();
        *inline.decor_mut() = o.decor().clone();
        *o = inline;
        return;
    }
    *new.decor_mut() = old.decor().clone();
    *old = new;
}

/// Element by element, in order: the first `min(len)` merged, extra old elements dropped,
/// extra new ones added.
fn merge_array(old: &mut ArrayOfTables, new: ArrayOfTables) {
    let n = new.len();
    while old.len() > n {
        old.remove(old.len() - 1);
    }
    for (i, table) in new.into_iter().enumerate() {
        match old.get_mut(i) {
            Some(o) => merge_table(o, table),
            None => old.push(table),
        }
    }
}

/// Whether two values mean the same: numbers by value (`1` and `1.0` alike), strings by their
/// contents whatever the quoting, arrays and inline tables element by element.
fn same(a: &Value, b: &Value) -> bool {
    let number = |v: &Value| match v {
        Value::Integer(i) => Some(*i.value() as f64),
        Value::Float(f) => Some(*f.value()),
        _ => None,
    };
    match (a, b) {
        (Value::String(x), Value::String(y)) => x.value() == y.value(),
        (Value::Boolean(x), Value::Boolean(y)) => x.value() == y.value(),
        (Value::Datetime(x), Value::Datetime(y)) => x.value() == y.value(),
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y.iter()).all(|(p, q)| same(p, q))
        }
        (Value::InlineTable(x), Value::InlineTable(y)) => {
            x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| same(v, w)))
        }
        _ => match (number(a), number(b)) {
            (Some(x), Some(y)) => x == y,
            _ => false,
        },
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::SceneFile;
    use super::tests_support::ORIGINAL;

    use super::tests_support::parsed;

    #[test]
    fn unchanged_file_is_the_original_text() {
        let text = parsed().to_toml_over(ORIGINAL).unwrap();
        assert_eq!(text, ORIGINAL);
    }

    #[test]
    fn changed_values_keep_their_comments_and_removed_ones_go() {
        let mut file = parsed();
        file.meshes[0].transform.translate = Some([1.0, 2.0, 7.5]);
        file.measurements.clear();
        file.output.size = Some([640, 480]);
        let text = file.to_toml_over(ORIGINAL).unwrap();
        assert!(text.starts_with("# A shoulder plan: the stem seated by hand.\n"));
        assert!(text.contains("# The stem, from the vendor's STL.\n[[mesh]]"));
        assert!(text.contains("size = [640, 480]   # small for the report"));
        assert!(text.contains("# seated by eye"), "{text}");
        assert!(text.contains("7.5"), "{text}");
        assert!(text.contains("transfer = 'ct-bone'"), "{text}");
        assert!(!text.contains("[[measurement]]"), "{text}");
        assert!(!text.contains("gap"), "{text}");
        // And it reads back to the file written.
        let back = SceneFile::parse(&text, Path::new("plan.toml")).unwrap();
        assert_eq!(back.meshes[0].transform.translate, Some([1.0, 2.0, 7.5]));
        assert!(back.measurements.is_empty());
        assert_eq!(back.output.size, Some([640, 480]));
    }

    #[test]
    fn new_elements_are_added_and_read_back() {
        let mut file = parsed();
        let mut second = file.measurements[0].clone();
        second.label = Some("second".into());
        file.measurements.push(second);
        file.meshes[0].transform.rotate_degrees = Some([0.0, 0.0, -10.0]);
        let text = file.to_toml_over(ORIGINAL).unwrap();
        let back = SceneFile::parse(&text, Path::new("plan.toml")).unwrap();
        assert_eq!(back.measurements.len(), 2);
        assert_eq!(back.measurements[1].label.as_deref(), Some("second"));
        assert_eq!(
            back.meshes[0].transform.rotate_degrees,
            Some([0.0, 0.0, -10.0])
        );
        assert!(text.contains("label = \"gap\""), "{text}");
    }

    #[test]
    fn an_original_that_is_no_toml_is_refused() {
        assert!(parsed().to_toml_over("[[mesh\n").is_err());
    }
}

#[cfg(test)]
mod path_tests {
    use std::path::Path;

    use super::tests_support::parsed;

    #[test]
    fn paths_are_written_relative_to_the_plan_folder() {
        let mut file = parsed();
        file.volumes[0].path = "/cases/ct/shoulder.nrrd".into();
        file.meshes[0].path = "/cases/plans/stem.stl".into();
        let mut builtin = file.meshes[0].clone();
        builtin.path = "data:stl/stem.stl".into();
        file.meshes.push(builtin);
        let rel = file.with_paths_relative_to(Path::new("/cases/plans"));
        assert_eq!(rel.volumes[0].path, "../ct/shoulder.nrrd");
        assert_eq!(rel.meshes[0].path, "stem.stl");
        assert_eq!(rel.meshes[1].path, "data:stl/stem.stl");
        // Back to absolute against the same folder: the same paths.
        let abs = rel.with_paths_from(Path::new("/cases/plans"));
        assert_eq!(
            Path::new(&abs.volumes[0].path),
            Path::new("/cases/plans/../ct/shoulder.nrrd")
        );
    }
}

#[cfg(test)]
mod tests_support {
    use std::path::Path;

    use super::SceneFile;

    pub const ORIGINAL: &str = r#"# A shoulder plan: the stem seated by hand.
[output]
size = [320, 240]   # small for the report

[[volume]]
path = "ct/shoulder.nrrd"
transfer = 'ct-bone'

# The stem, from the vendor's STL.
[[mesh]]
path = "stem.stl"
color = [0.8, 0.8, 0.9]
transform = { translate = [1, 2, 3] } # seated by eye

[[measurement]]
kind = "distance"
points = [[0, 0, 0], [10, 0, 0]]
label = "gap"
"#;

    pub fn parsed() -> SceneFile {
        SceneFile::parse(ORIGINAL, Path::new("plan.toml")).unwrap()
    }
}
