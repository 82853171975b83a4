//! The patient frame: orientation codes of volume axes, named views (anterior, superior, ...)
//! and the patient-direction letters of a world direction.
//!
//! The world is patient RAS millimetres: +x toward the patient's right, +y anterior, +z
//! superior (NIfTI's and nibabel's convention; DICOM's LPS differs by the sign of x and y).
//! A letter of an orientation code names the direction its axis *increases toward*, as in
//! nibabel's `aff2axcodes`: `LPI` is a grid whose first index runs toward the patient's left,
//! the second posterior and the third inferior. (ITK's `SpatialOrientation` names run the other
//! way; its `RAI` is this `LPS`.)

use std::fmt;
use std::str::FromStr;

use glam::{DMat3, DVec3};
use thiserror::Error;

/// A patient direction and its RAS unit vector.
const LETTERS: [(char, DVec3); 6] = [
    ('R', DVec3::X),
    ('L', DVec3::NEG_X),
    ('A', DVec3::Y),
    ('P', DVec3::NEG_Y),
    ('S', DVec3::Z),
    ('I', DVec3::NEG_Z),
];

/// Why an orientation code or a view name was refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum PatientError {
    /// An orientation code that is not three letters, one from each of R/L, A/P and S/I.
    #[error(
        "orientation {0:?} is not three letters naming where each index axis runs, one each from R/L, A/P and S/I (for example RAS, LPS, LPI)"
    )]
    BadOrientation(String),
    /// A view name with an unknown word.
    #[error(
        "view {name:?}: {word:?} is not a direction; a view is anterior, posterior, left, right, superior or inferior, or several joined by '-' (anterior-right, anterolateral-right, posterosuperior-left)"
    )]
    UnknownView {
        /// The whole name.
        name: String,
        /// The word not understood.
        word: String,
    },
    /// A view whose parts cancel (anterior-posterior) or that says lateral or medial without
    /// a side.
    #[error("view {name:?}: {why}")]
    BadView {
        /// The whole name.
        name: String,
        /// What is wrong.
        why: &'static str,
    },
}

/// Where the three index axes of a grid run, in the patient frame: `LPS`, `RAS`, `LPI`...
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OrientationCode([char; 3]);

impl OrientationCode {
    /// `RAS`: the index axes along world +x, +y, +z.
    pub const RAS: Self = Self(['R', 'A', 'S']);

    /// The direction matrix whose columns are the index axes' unit vectors in RAS.
    pub fn direction(self) -> DMat3 {
        let [x, y, z] = self.0.map(letter_vector);
        DMat3::from_cols(x, y, z)
    }
}

fn letter_vector(letter: char) -> DVec3 {
    LETTERS
        .iter()
        .find(|(l, _)| *l == letter)
        .map_or(DVec3::ZERO, |(_, v)| *v)
}

impl FromStr for OrientationCode {
    type Err = PatientError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || PatientError::BadOrientation(s.to_owned());
        let letters: Vec<char> = s.trim().chars().map(|c| c.to_ascii_uppercase()).collect();
        let [a, b, c] = letters.as_slice() else {
            return Err(bad());
        };
        let code = [*a, *b, *c];
        let axes = code.map(|l| LETTERS.iter().position(|(m, _)| *m == l).map(|i| i / 2));
        let mut seen = [false; 3];
        for axis in axes {
            let axis = axis.ok_or_else(bad)?;
            if std::mem::replace(&mut seen[axis], true) {
                return Err(bad());
            }
        }
        Ok(Self(code))
    }
}

impl fmt::Display for OrientationCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [a, b, c] = self.0;
        write!(f, "{a}{b}{c}")
    }
}

/// A view named by the side of the patient it looks from, in the patient frame.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedView {
    /// The name as given, lower case (used in output file names).
    pub name: String,
    /// Unit vector from the patient toward the eye, in RAS.
    pub from: DVec3,
    /// Screen up, in RAS: superior, or anterior for views along the body axis.
    pub up: DVec3,
}

/// The single view directions, for messages and documentation.
pub const VIEW_WORDS: [&str; 6] = [
    "anterior",
    "posterior",
    "left",
    "right",
    "superior",
    "inferior",
];

impl NamedView {
    /// Parses a name: one of [`VIEW_WORDS`], or several joined by `-` (`anterior-right`),
    /// where a word may also be a compound such as `anterolateral`, `posteromedial` or
    /// `superolateral` (`lateral` and `medial` then need `left` or `right` beside them: the
    /// side whose outside or inside is seen; `anterolateral-right` looks from the front and
    /// the patient's right).
    pub fn parse(name: &str) -> Result<Self, PatientError> {
        let lower = name.trim().to_ascii_lowercase();
        let mut sum = DVec3::ZERO;
        let (mut side, mut lateral, mut medial) = (None, false, false);
        for word in lower.split('-') {
            for part in split_compound(word).ok_or_else(|| PatientError::UnknownView {
                name: name.to_owned(),
                word: word.to_owned(),
            })? {
                match part {
                    "lateral" => lateral = true,
                    "medial" => medial = true,
                    _ => {
                        let v = word_vector(part);
                        if v.x != 0.0 {
                            side = Some(v.x);
                        }
                        sum += v;
                    }
                }
            }
        }
        let bad = |why| PatientError::BadView {
            name: name.to_owned(),
            why,
        };
        if lateral || medial {
            let side = side.ok_or_else(|| bad("lateral and medial need left or right"))?;
            if lateral && medial {
                return Err(bad("lateral and medial cancel"));
            }
            // The side word already counts once toward that side; medial looks from the
            // other side instead.
            if medial {
                sum.x -= 2.0 * side;
            }
        }
        let from = sum
            .try_normalize()
            .ok_or_else(|| bad("its directions cancel"))?;
        let up = if from.z.abs() > 0.999 {
            DVec3::Y
        } else {
            (DVec3::Z - from * from.z).normalize()
        };
        Ok(Self {
            name: lower,
            from,
            up,
        })
    }
}

/// The parts of one word of a view name (`anterolateral` is `anterior` and `lateral`), or
/// `None` for an unknown word.
fn split_compound(word: &str) -> Option<Vec<&'static str>> {
    const PREFIXES: [(&str, &str); 4] = [
        ("antero", "anterior"),
        ("postero", "posterior"),
        ("supero", "superior"),
        ("infero", "inferior"),
    ];
    if let Some(w) = VIEW_WORDS
        .iter()
        .chain(&["lateral", "medial"])
        .find(|w| **w == word)
    {
        return Some(vec![w]);
    }
    let (prefix, full) = PREFIXES.iter().find(|(p, _)| word.starts_with(p))?;
    let mut rest = split_compound(&word[prefix.len()..])?;
    rest.insert(0, full);
    Some(rest)
}

fn word_vector(word: &str) -> DVec3 {
    match word {
        "anterior" => DVec3::Y,
        "posterior" => DVec3::NEG_Y,
        "left" => DVec3::NEG_X,
        "right" => DVec3::X,
        "superior" => DVec3::Z,
        "inferior" => DVec3::NEG_Z,
        _ => DVec3::ZERO,
    }
}

/// How patient directions lie in the world: the rotation from RAS to world (the identity
/// unless the volume that defines the patient frame sits under a rotated node).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PatientFrame {
    /// Columns: the world directions of patient R, A and S.
    pub to_world: DMat3,
}

impl Default for PatientFrame {
    fn default() -> Self {
        Self {
            to_world: DMat3::IDENTITY,
        }
    }
}

impl PatientFrame {
    /// The frame of a node whose world transform has this linear part: its columns
    /// normalised and made orthogonal (a scale or shear in the node does not tilt the letters).
    pub fn from_linear(linear: DMat3) -> Self {
        let x = linear.x_axis.try_normalize().unwrap_or(DVec3::X);
        let y = (linear.y_axis - x * x.dot(linear.y_axis))
            .try_normalize()
            .unwrap_or(DVec3::Y);
        let handed = x.cross(y);
        let z = if handed.dot(linear.z_axis) < 0.0 {
            -handed
        } else {
            handed
        };
        Self {
            to_world: DMat3::from_cols(x, y, z),
        }
    }

    /// The world direction of a patient (RAS) direction.
    pub fn world(&self, patient: DVec3) -> DVec3 {
        self.to_world * patient
    }

    /// The patient (RAS) direction of a world direction.
    pub fn patient(&self, world: DVec3) -> DVec3 {
        self.to_world.inverse() * world
    }

    /// World superior: the axis orbits turn about when the scene gives none.
    pub fn superior(&self) -> DVec3 {
        self.world(DVec3::Z)
    }

    /// The letters of a world direction, strongest first: `R`, `A`, `S`... for directions
    /// along an axis, `RA` or `SRP` for oblique ones (a letter is added while its component is
    /// over 0.3, about 17 degrees off the dominant axes). Empty for a zero direction.
    pub fn letters(&self, world: DVec3) -> String {
        let Some(p) = self.patient(world).try_normalize() else {
            return String::new();
        };
        let mut parts: Vec<(f64, char)> = [0, 1, 2]
            .iter()
            .map(|&a| {
                let c = p[a];
                let letter = LETTERS[2 * a + usize::from(c < 0.0)].0;
                (c.abs(), letter)
            })
            .collect();
        parts.sort_by(|a, b| b.0.total_cmp(&a.0));
        parts
            .iter()
            .enumerate()
            .filter(|(i, (c, _))| *i == 0 || *c > 0.3)
            .map(|(_, (_, l))| *l)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orientation_codes_give_direction_columns() {
        let lpi: OrientationCode = "lpi".parse().unwrap();
        assert_eq!(lpi.to_string(), "LPI");
        assert_eq!(
            lpi.direction(),
            DMat3::from_cols(DVec3::NEG_X, DVec3::NEG_Y, DVec3::NEG_Z)
        );
        let sar: OrientationCode = "SAR".parse().unwrap();
        assert_eq!(sar.direction() * DVec3::X, DVec3::Z);
        assert_eq!(sar.direction() * DVec3::Z, DVec3::X);
        for bad in ["", "RA", "RASS", "RRS", "RLS", "XYZ", "R A"] {
            assert!(bad.parse::<OrientationCode>().is_err(), "{bad}");
        }
    }

    #[test]
    fn named_views_look_from_their_side_with_superior_up() {
        let anterior = NamedView::parse("anterior").unwrap();
        assert_eq!(anterior.from, DVec3::Y);
        assert_eq!(anterior.up, DVec3::Z);
        let superior = NamedView::parse("Superior").unwrap();
        assert_eq!(superior.from, DVec3::Z);
        assert_eq!(
            superior.up,
            DVec3::Y,
            "anterior at the top of a superior view"
        );
        let al = NamedView::parse("anterolateral-right").unwrap();
        assert!(
            al.from
                .abs_diff_eq(DVec3::new(1.0, 1.0, 0.0).normalize(), 1e-12)
        );
        let pm = NamedView::parse("posteromedial-right").unwrap();
        assert!(
            pm.from
                .abs_diff_eq(DVec3::new(-1.0, -1.0, 0.0).normalize(), 1e-12)
        );
        let ass = NamedView::parse("anterosuperior").unwrap();
        assert!(ass.up.dot(ass.from).abs() < 1e-12 && ass.up.z > 0.0);
        for bad in [
            "front",
            "anterior-posterior",
            "lateral",
            "",
            "anterior--right",
        ] {
            assert!(NamedView::parse(bad).is_err(), "{bad}");
        }
        let message = NamedView::parse("front").unwrap_err().to_string();
        assert!(
            message.contains("front") && message.contains("superior"),
            "{message}"
        );
    }

    #[test]
    fn letters_name_the_strongest_directions_first() {
        let frame = PatientFrame::default();
        assert_eq!(frame.letters(DVec3::X), "R");
        assert_eq!(frame.letters(DVec3::new(-1.0, 0.0, -0.1)), "L");
        assert_eq!(frame.letters(DVec3::new(0.5, -1.0, 0.0)), "PR");
        assert_eq!(frame.letters(DVec3::ZERO), "");
        // A frame turned 90 degrees about S: world +x is then patient anterior.
        let turned =
            PatientFrame::from_linear(DMat3::from_rotation_z(-std::f64::consts::FRAC_PI_2));
        assert_eq!(turned.letters(DVec3::X), "A");
        assert!(turned.superior().abs_diff_eq(DVec3::Z, 1e-12));
    }
}
