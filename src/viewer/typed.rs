//! A placement typed in (the `E` key): `x 2.5` moves the selected mesh 2.5 mm along the
//! patient's x (R), `rz -10` turns it 10 degrees back about the z (S) axis through its pivot,
//! `x=12.5` puts its pivot at x = 12.5 mm; several in one line (`x 2.5 rz -10`) are one edit,
//! undone with Ctrl+Z.

use glam::{DMat4, DVec3};

use super::edit::{Editor, LabelKey, Notice};
use super::plan;

/// The largest move typed, in millimetres, and turn, in degrees: more is a typing slip.
const MAX_MM: f64 = 10_000.0;
const MAX_DEGREES: f64 = 3_600.0;

/// One step of a typed placement, along or about a patient axis (0 x R, 1 y A, 2 z S).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Step {
    /// Move this many millimetres along the axis.
    Move(usize, f64),
    /// Turn this many degrees about the axis through the pivot.
    Turn(usize, f64),
    /// Put the pivot at this coordinate along the axis.
    Set(usize, f64),
}

/// The steps of a typed line: names `x`, `y`, `z` (millimetres; `x=12.5` sets the pivot's
/// coordinate) and `rx`, `ry`, `rz` (degrees), each followed by a number.
///
/// # Errors
///
/// A name that is none of those, a missing or non-finite number, a move past 10 m or a turn
/// past ten whole turns, or nothing at all: a message that says which.
pub fn parse_placement(text: &str) -> Result<Vec<Step>, String> {
    // `x=12.5` and `x = 12.5` read as `x = 12.5`.
    let spaced = text.replace('=', " = ");
    let mut words = spaced.split_whitespace().peekable();
    let mut steps = Vec::new();
    while let Some(name) = words.next() {
        let lower = name.to_ascii_lowercase();
        let (turn, axis) = match lower.as_str() {
            "x" => (false, 0),
            "y" => (false, 1),
            "z" => (false, 2),
            "rx" => (true, 0),
            "ry" => (true, 1),
            "rz" => (true, 2),
            _ => {
                return Err(format!(
                    "{name:?} is not x, y, z (mm) or rx, ry, rz (degrees)"
                ));
            }
        };
        let set = words.peek() == Some(&"=");
        if set {
            words.next();
            if turn {
                return Err(format!(
                    "{name}=: turns are typed relative (rz -10); only x, y and z can be set"
                ));
            }
        }
        let value = words
            .next()
            .ok_or_else(|| format!("{name}: a number must follow"))?;
        let v: f64 = value
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .ok_or_else(|| format!("{name} {value}: {value:?} is not a number"))?;
        let limit = if turn { MAX_DEGREES } else { MAX_MM };
        if v.abs() > limit {
            return Err(format!("{name} {v}: more than {limit} at once"));
        }
        steps.push(match (turn, set) {
            (true, _) => Step::Turn(axis, v),
            (false, true) => Step::Set(axis, v),
            (false, false) => Step::Move(axis, v),
        });
    }
    if steps.is_empty() {
        return Err("nothing typed".into());
    }
    Ok(steps)
}

/// `local` (of a top node whose pivot is at `pivot`) after `steps`, the axes being the
/// patient's `axes` (R, A, S in the world).
pub fn placed(local: DMat4, pivot: DVec3, steps: &[Step], axes: [DVec3; 3]) -> DMat4 {
    let mut local = local;
    let mut pivot = pivot;
    for step in steps {
        match *step {
            Step::Move(a, mm) => {
                local = plan::translated(local, axes[a] * mm);
                pivot += axes[a] * mm;
            }
            Step::Set(a, mm) => {
                let delta = axes[a] * (mm - pivot.dot(axes[a]));
                local = plan::translated(local, delta);
                pivot += delta;
            }
            Step::Turn(a, degrees) => local = plan::rotated(local, pivot, axes[a], degrees),
        }
    }
    local
}

impl Editor {
    /// A key while a placement is typed ([`Editor::placing`] is `Some`): Enter moves the
    /// selected mesh as one edit, Escape drops the line.
    pub fn place_key(&mut self, key: LabelKey<'_>) -> Option<Notice> {
        let typed = self.placing.as_mut()?;
        match key {
            LabelKey::Enter => {
                let text = typed.clone();
                self.placing = None;
                let steps = match parse_placement(&text) {
                    Ok(steps) => steps,
                    Err(e) => return Some(Notice::Say(format!("not placed: {e}"))),
                };
                let patient = self.scene.patient_frame();
                let axes = [DVec3::X, DVec3::Y, DVec3::Z].map(|d| patient.world(d));
                self.move_selected(|local, pivot| placed(local, pivot, &steps, axes))
            }
            LabelKey::Escape => {
                self.placing = None;
                Some(Notice::Print("placement cancelled".into()))
            }
            LabelKey::Backspace => {
                typed.pop();
                None
            }
            LabelKey::Text(text) => {
                if let Some(t) = text
                    && typed.len() < 200
                {
                    typed.extend(t.chars().filter(|c| !c.is_control()));
                }
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn typed_placements_read_as_moves_turns_and_settings() {
        assert_eq!(
            parse_placement("x 2.5 rz -10").unwrap(),
            [Step::Move(0, 2.5), Step::Turn(2, -10.0)]
        );
        assert_eq!(
            parse_placement("X=12.5 y = -3  z 1e1").unwrap(),
            [Step::Set(0, 12.5), Step::Set(1, -3.0), Step::Move(2, 10.0)]
        );
        for bad in [
            "", "w 3", "x", "x nan", "x inf", "rz=10", "x 20000", "rx 4000", "x 2 y",
        ] {
            assert!(parse_placement(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn steps_move_and_turn_about_the_pivot_as_typed() {
        let axes = [DVec3::X, DVec3::Y, DVec3::Z];
        let pivot = DVec3::new(10.0, 0.0, 0.0);
        let local = DMat4::from_translation(pivot);
        // Turned 90 degrees about z through the pivot: the pivot stays, +x goes to +y.
        let turned = placed(local, pivot, &[Step::Turn(2, 90.0)], axes);
        assert!(
            turned
                .transform_point3(DVec3::ZERO)
                .abs_diff_eq(pivot, 1e-9)
        );
        assert!(
            turned
                .transform_vector3(DVec3::X)
                .abs_diff_eq(DVec3::Y, 1e-9)
        );
        // Moved, then set: the pivot ends where x= put it, y moved by 3.
        let moved = placed(
            local,
            pivot,
            &[Step::Move(1, 3.0), Step::Set(0, -5.0)],
            axes,
        );
        assert!(
            moved
                .transform_point3(DVec3::ZERO)
                .abs_diff_eq(DVec3::new(-5.0, 3.0, 0.0), 1e-9)
        );
    }
}
