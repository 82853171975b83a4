use super::*;

fn scene_path() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/scenes/shoulder.toml")
        .display()
        .to_string()
}

fn planned(text: &str) -> Result<Vec<PlannedJob>, Vec<Problem>> {
    let manifest = parse(text).map_err(|e| {
        vec![Problem {
            job: "parse".into(),
            key: String::new(),
            message: e,
        }]
    })?;
    plan(&manifest, Path::new("."))
}

fn problems(text: &str) -> Vec<String> {
    match planned(text) {
        Ok(_) => panic!("accepted: {text}"),
        Err(p) => p.iter().map(ToString::to_string).collect(),
    }
}

#[test]
fn defaults_fill_jobs_and_names_hold_what_varies() {
    let text = format!(
        "[defaults]\nviews = [\"anterior\", \"left\"]\nsizes = [[64, 48]]\n\n[[job]]\nscene = \"{0}\"\n\n[[job]]\nname = \"wide\"\nscene = \"{0}\"\nsizes = [[64, 48], [128, 96]]\norderings = [\"btf\", \"pbtf\"]\ncontents = [\"meshes\", \"all\"]\n",
        scene_path()
    );
    let jobs = planned(&text).unwrap();
    // The first job is named after its scene file.
    assert_eq!(jobs[0].name, "shoulder");
    let names: Vec<String> = jobs[0]
        .items
        .iter()
        .map(|i| i.image.display().to_string())
        .collect();
    assert_eq!(names, ["shoulder-anterior.png", "shoulder-left.png"]);
    let wide = &jobs[1];
    assert_eq!(wide.items.len(), 2 * 2 * 2 * 2);
    // Pictures with volumes come first, so a volume is classified once.
    assert_eq!(wide.items[0].content, Content::All);
    assert_eq!(wide.items.last().unwrap().content, Content::Meshes);
    assert_eq!(
        wide.items[0].image,
        PathBuf::from("wide-anterior-all-btf-64x48.png")
    );
}

#[test]
fn keys_that_cannot_mean_anything_are_refused() {
    let s = scene_path();
    for (text, expected) in [
        (
            format!("[defaults]\nscene = \"{s}\"\n[[job]]\nname = \"a\"\nscene = \"{s}\"\n"),
            "defaults, key `scene`: belongs to a job",
        ),
        ("".to_owned(), "no [[job]] tables"),
        (
            format!("[[job]]\nscene = \"{s}\"\nvolume = \"x.nrrd\"\n"),
            "a scene or a volume, not both",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\nviews = []\n"),
            "key `views`: is empty",
        ),
        (
            format!(
                "[[job]]\nscene = \"{s}\"\nviews = [{{ name = \"o\", view_from = [0, 0, 0] }}]\n"
            ),
            "up and view_from must not be zero",
        ),
        (
            format!(
                "[[job]]\nscene = \"{s}\"\nviews = [{{ name = \"o\", eye = [1, 2, 3], target = [1, 2, 3] }}]\n"
            ),
            "eye and target are the same point",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\nviews = [\"right\", \"right\"]\n"),
            "\"right\" is given twice",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\nout = \"{{case}}.png\"\n"),
            "unknown placeholder {case}",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\nout = \"x.jpg\"\n"),
            "end the name with .png",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\nout = \"index.json\"\n"),
            "key `out`",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\nsizes = [[20000, 10]]\n"),
            "between 1 and 16384",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\nsizes = [[16384, 16384]]\n"),
            "pixels in one image",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\ndepth_mode = \"surface\"\n"),
            "has no effect without `depth`",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\nwindow = [200, 100]\n"),
            "must lie below",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\nmeasurements = \"m.json\"\n"),
            "no [[measurement]]",
        ),
        (
            format!("[[job]]\nname = \"a/b\"\nscene = \"{s}\"\n"),
            "goes into file names",
        ),
        (
            format!("[[job]]\nscene = \"{s}\"\nannotate = \"arrows\"\n"),
            "not an annotation",
        ),
    ] {
        let found = problems(&text);
        assert!(
            found.iter().any(|p| p.contains(expected)),
            "{expected:?} not in {found:?}"
        );
    }
}

#[test]
fn unknown_keys_and_wrong_types_name_the_key() {
    let e = parse("[[job]]\nscene = \"s.toml\"\nveiws = [\"anterior\"]\n").unwrap_err();
    assert!(e.contains("veiws"), "{e}");
    let e = parse("[[job]]\nscene = \"s.toml\"\nviews = [3]\n").unwrap_err();
    assert!(e.contains("a view is a name"), "{e}");
}
