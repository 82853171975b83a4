//! The slices a run asks for, as values: a kind of plane and where along its normal it lies
//! (`axial@-62.5`), read from the command line and scene files alike. Where the plane then
//! lies in a scene, and what it shows, is `crate::slice`'s.

/// A name that is no slice plane.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "slice {0:?} is not a plane: axial, coronal, sagittal, implant-long or implant-cross, optionally with @MM along its normal (axial@-62.5)"
)]
pub struct BadSliceSpec(pub String);

/// The kinds of slice plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PlaneKind {
    /// Normal to the patient's superior axis, seen from the feet (the patient's right on the
    /// image's left, anterior up).
    Axial,
    /// Normal to the anterior axis, seen from the front (right on the left, superior up).
    Coronal,
    /// Normal to the right axis, seen from the patient's left (anterior on the left, superior
    /// up).
    Sagittal,
    /// Through an implant's pivot, containing its long axis (superior end up), normal to the
    /// patient's anterior axis made square to that axis: a coronal plane turned with the
    /// implant.
    ImplantLong,
    /// Through an implant's pivot, normal to its long axis, seen from its inferior end: an
    /// axial plane turned with the implant.
    ImplantCross,
}

impl PlaneKind {
    /// Every kind, in the order names are listed.
    pub const ALL: [Self; 5] = [
        Self::Axial,
        Self::Coronal,
        Self::Sagittal,
        Self::ImplantLong,
        Self::ImplantCross,
    ];

    /// The name on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Self::Axial => "axial",
            Self::Coronal => "coronal",
            Self::Sagittal => "sagittal",
            Self::ImplantLong => "implant-long",
            Self::ImplantCross => "implant-cross",
        }
    }

    /// Whether the plane follows a mesh.
    pub fn follows_implant(self) -> bool {
        matches!(self, Self::ImplantLong | Self::ImplantCross)
    }
}

/// A slice asked for: a kind of plane and, optionally, where along its normal it lies (for the
/// patient planes the world coordinate along the normal, `axial@-62.5` being the plane
/// z = -62.5 in RAS; for the implant planes the distance from the pivot along the normal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SliceSpec {
    /// The kind of plane.
    pub kind: PlaneKind,
    /// Millimetres along the normal; `None` puts the plane through the given point (the
    /// camera's target) or the implant's pivot.
    pub at_mm: Option<f64>,
}

impl std::str::FromStr for SliceSpec {
    type Err = BadSliceSpec;

    fn from_str(s: &str) -> Result<Self, BadSliceSpec> {
        let bad = || BadSliceSpec(s.to_owned());
        let (name, at) = match s.trim().split_once('@') {
            Some((name, at)) => (name.trim(), Some(at.trim())),
            None => (s.trim(), None),
        };
        let kind = PlaneKind::ALL
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(bad)?;
        let at_mm = match at {
            Some(at) => {
                let v: f64 = at.parse().map_err(|_| bad())?;
                if !v.is_finite() {
                    return Err(bad());
                }
                Some(v)
            }
            None => None,
        };
        Ok(Self { kind, at_mm })
    }
}

impl std::fmt::Display for SliceSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.kind.name())?;
        if let Some(at) = self.at_mm {
            write!(f, "@{at}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slice_names_read_and_write() {
        let s: SliceSpec = "axial@-62.5".parse().unwrap();
        assert_eq!(s.kind, PlaneKind::Axial);
        assert_eq!(s.at_mm, Some(-62.5));
        assert_eq!(s.to_string(), "axial@-62.5");
        let s: SliceSpec = "implant-cross".parse().unwrap();
        assert_eq!((s.kind, s.at_mm), (PlaneKind::ImplantCross, None));
        for bad in ["oblique", "axial@", "axial@nan", "axial@inf", "@3", ""] {
            assert!(bad.parse::<SliceSpec>().is_err(), "{bad}");
        }
    }
}
