//! Keys to actions: what each key of [`KEYS`] asks for, decided from the key and the
//! modifiers alone, with no window and no state. The window's loop carries the action out
//! (the view's actions itself, the plan's through [`super::edit::Editor`]).

use winit::keyboard::{Key, ModifiersState, NamedKey};

use crate::order::Ordering;

/// Every key of the viewer and what it does, as `H` shows them and `view --help` lists them.
pub const KEYS: &[(&str, &str)] = &[
    ("left drag", "orbit about the scene's up"),
    ("right drag", "pan"),
    ("wheel", "zoom"),
    (
        "click",
        "pick (a JSON line on stdout); on a mesh, select it",
    ),
    (
        "drag on it",
        "move the selected mesh in the view plane (also Shift+drag)",
    ),
    ("Ctrl+drag", "turn the selected mesh about its pivot"),
    (
        "Shift+wheel",
        "move the selected mesh along the view direction",
    ),
    ("arrows", "move the selected mesh by 1 mm (Shift: 10 mm)"),
    ("Ctrl+arrows", "turn it by 1 degree (Shift: 10)"),
    ("+ / -", "move it toward / away from the eye by 1 mm"),
    (
        "E",
        "type a placement: x 2.5, rz -10, x=12.5 (pivot's x); Enter",
    ),
    ("Ctrl+Z, Ctrl+Y", "undo, redo"),
    ("M", "measure: distance, angle, line angle, point, off"),
    (
        "N",
        "snap: click a point of the selected mesh, then where it goes",
    ),
    ("X", "clear the points clicked so far"),
    ("Tab", "select the next measurement"),
    ("L", "label the selected measurement (type, Enter)"),
    ("Delete", "delete the selected measurement"),
    ("Ctrl+S", "save the plan as a new scene file"),
    ("F5", "reload the scene file from disk"),
    (
        "1-7",
        "ordering: BTF, PBTF, IP-PBTF, exact, bucketed, pyramid, rows",
    ),
    (
        "T",
        "transfer function: the scene's, then the presets that fit the data",
    ),
    (
        "Alt+drag",
        "window: right raises the level, up narrows the width",
    ),
    ("A", "annotations off and on"),
    ("S", "screenshot and its scene file"),
    ("C, [, ]", "clip plane on and off, move it"),
    (
        "B, {, }",
        "crop box around the selected mesh on and off, shrink, grow by 5 mm",
    ),
    ("R", "reset the camera"),
    (
        "K",
        "contact: what the selected mesh's surface touches in the volume",
    ),
    (
        "Shift+K",
        "contact map: the selected mesh painted with the value under it",
    ),
    (
        "V",
        "four panes: 3D, axial, sagittal, coronal; a click sets their crosshair",
    ),
    (
        "wheel on a slice",
        "move its plane; Alt+drag on it windows the slices",
    ),
    (
        "drag on it in a slice",
        "move the selected mesh in that slice's plane",
    ),
    (
        "I",
        "four panes: the implant's long axis for the coronal pane",
    ),
    ("O", "the selected mesh's opacity: 100, 60, 30%"),
    (
        "Shift+O",
        "the selected mesh's colour: its own, bone, steel, cement, red, green, blue",
    ),
    ("H", "this help"),
    ("Escape", "cancel, deselect; with nothing to cancel, quit"),
    (
        "Q",
        "quit; with unsaved edits it asks (S save, D discard, Escape back)",
    ),
];

/// The keys as text, one per line (for `view --help`).
pub fn keys_help() -> String {
    let mut text = String::from("Keys and mouse in the window:\n");
    for (keys, what) in KEYS {
        text.push_str(&format!("  {keys:<16} {what}\n"));
    }
    text
}

/// A step of the arrow and +/- keys: 1 mm, or 1 degree with Ctrl; ten with Shift.
pub const STEP: f64 = 1.0;

/// The keys 1 to 7 and the orderings they choose.
pub const ORDERINGS: [(&str, Ordering); 7] = [
    ("1", Ordering::Btf),
    ("2", Ordering::Pbtf),
    ("3", Ordering::IpPbtfImplicit),
    ("4", Ordering::Exact),
    ("5", Ordering::Bucketed),
    ("6", Ordering::Pyramid),
    ("7", Ordering::Rows),
];

/// One of the screen's axes, as the camera shows them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScreenAxis {
    /// To the right of the screen.
    Right,
    /// Up the screen.
    Up,
    /// Away from the eye, into the screen.
    Forward,
}

/// What a key asks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Action {
    /// Escape: cancel what is under way (snap, the points clicked, measure mode, the
    /// selection), or quit when nothing is.
    Cancel,
    /// Quit.
    Quit,
    /// Read the scene file again.
    Reload,
    /// Select the next measurement.
    NextMeasurement,
    /// Delete the selected measurement (the last one when none is selected).
    DeleteMeasurement,
    /// Move the selected mesh by `mm` along a screen axis.
    Nudge {
        /// The axis.
        along: ScreenAxis,
        /// Millimetres, signed.
        mm: f64,
    },
    /// Turn the selected mesh about its pivot by `degrees` about a screen axis.
    Turn {
        /// The axis.
        about: ScreenAxis,
        /// Degrees, signed (right-handed about the axis).
        degrees: f64,
    },
    /// Undo the last edit.
    Undo,
    /// Redo the last edit undone.
    Redo,
    /// Save the plan as a new scene file.
    SavePlan,
    /// Save a screenshot and its scene file.
    Screenshot,
    /// The next transfer function preset.
    NextPreset,
    /// Show or hide the key help.
    ToggleHelp,
    /// The next measurement kind (distance, angle, line angle, point, off).
    NextMeasureKind,
    /// Snap mode: a point of the selected mesh, then where it goes.
    Snap,
    /// Report the selected mesh's contact with the volume (the first mesh's where none is
    /// selected).
    Contact,
    /// Forget the points clicked so far.
    ClearPoints,
    /// Start typing the selected measurement's label.
    Label,
    /// Annotations off and on.
    ToggleAnnotations,
    /// The camera back where it began.
    ResetCamera,
    /// The clip plane on and off.
    ToggleClip,
    /// Move the clip plane by this many millimetres along its normal.
    MoveClip(f64),
    /// The crop box around the selected mesh on and off.
    ToggleCrop,
    /// Grow the crop box by this many millimetres on every side (shrink where negative).
    GrowCrop(f64),
    /// Draw the volumes in this ordering.
    Ordering(Ordering),
    /// One 3D view, or four panes (3D and three slices).
    TogglePanes,
    /// Type a placement of the selected mesh.
    Place,
    /// The fourth pane between coronal and the selected implant's long axis.
    ImplantPane,
    /// The contact map on the selected mesh on and off.
    ToggleContactMap,
    /// O: the selected mesh's opacity, in steps.
    MeshOpacity,
    /// Shift+O: the selected mesh's colour, from a palette.
    MeshColour,
}

impl Action {
    /// Whether a key held down repeats the action, as the system's key repeat sends it again:
    /// steps that move something (a mesh, the clip plane, the crop box's sides) and undo and
    /// redo. Every other action is taken once a press: a toggle held down would flicker (four
    /// panes on and off with every repeat), a held S would save screenshot after screenshot and
    /// a held Ctrl+S plan after plan.
    pub fn repeats(&self) -> bool {
        matches!(
            self,
            Action::Nudge { .. }
                | Action::Turn { .. }
                | Action::MoveClip(_)
                | Action::GrowCrop(_)
                | Action::Undo
                | Action::Redo
        )
    }
}

/// The action of `key` pressed with `modifiers` held; `None` for a key that does nothing.
/// (Typing a label takes the keys before this: see [`super::edit::LabelKey`].)
pub fn key_action(key: &Key, modifiers: ModifiersState) -> Option<Action> {
    let ctrl = modifiers.control_key();
    let shift = modifiers.shift_key();
    let step = STEP * if shift { 10.0 } else { 1.0 };
    match key {
        Key::Named(NamedKey::Escape) => Some(Action::Cancel),
        Key::Named(NamedKey::F5) => Some(Action::Reload),
        Key::Named(NamedKey::Tab) => Some(Action::NextMeasurement),
        Key::Named(NamedKey::Delete | NamedKey::Backspace) => Some(Action::DeleteMeasurement),
        Key::Named(arrow @ (NamedKey::ArrowLeft | NamedKey::ArrowRight)) => {
            let sign = if *arrow == NamedKey::ArrowLeft {
                -1.0
            } else {
                1.0
            };
            Some(if ctrl {
                // Left and right turn about the screen's up.
                Action::Turn {
                    about: ScreenAxis::Up,
                    degrees: sign * step,
                }
            } else {
                Action::Nudge {
                    along: ScreenAxis::Right,
                    mm: sign * step,
                }
            })
        }
        Key::Named(arrow @ (NamedKey::ArrowUp | NamedKey::ArrowDown)) => {
            let sign = if *arrow == NamedKey::ArrowUp {
                1.0
            } else {
                -1.0
            };
            Some(if ctrl {
                // Up tips the top away from the eye: a turn about the screen's left.
                Action::Turn {
                    about: ScreenAxis::Right,
                    degrees: -sign * step,
                }
            } else {
                Action::Nudge {
                    along: ScreenAxis::Up,
                    mm: sign * step,
                }
            })
        }
        Key::Character(c) => character_action(&c.to_lowercase(), ctrl, shift, step),
        _ => None,
    }
}

/// [`key_action`] for a key that types `c` (lower case).
fn character_action(c: &str, ctrl: bool, shift: bool, step: f64) -> Option<Action> {
    if ctrl {
        return match c {
            "z" if shift => Some(Action::Redo),
            "z" => Some(Action::Undo),
            "y" => Some(Action::Redo),
            "s" => Some(Action::SavePlan),
            _ => None,
        };
    }
    Some(match c {
        "+" | "=" => Action::Nudge {
            along: ScreenAxis::Forward,
            mm: -step,
        },
        "-" => Action::Nudge {
            along: ScreenAxis::Forward,
            mm: step,
        },
        "q" => Action::Quit,
        "s" => Action::Screenshot,
        "t" => Action::NextPreset,
        "h" => Action::ToggleHelp,
        "m" => Action::NextMeasureKind,
        "n" => Action::Snap,
        "x" => Action::ClearPoints,
        "k" if shift => Action::ToggleContactMap,
        "o" if shift => Action::MeshColour,
        "o" => Action::MeshOpacity,
        "k" => Action::Contact,
        "v" => Action::TogglePanes,
        "e" => Action::Place,
        "i" => Action::ImplantPane,
        "l" => Action::Label,
        "a" => Action::ToggleAnnotations,
        "r" => Action::ResetCamera,
        "c" => Action::ToggleClip,
        "b" => Action::ToggleCrop,
        "{" => Action::GrowCrop(-5.0),
        "}" => Action::GrowCrop(5.0),
        "[" => Action::MoveClip(-1.0),
        "]" => Action::MoveClip(1.0),
        digit => {
            return ORDERINGS
                .iter()
                .find(|(k, _)| *k == digit)
                .map(|(_, o)| Action::Ordering(*o));
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn press(c: &str, modifiers: ModifiersState) -> Option<Action> {
        key_action(&Key::Character(c.into()), modifiers)
    }

    fn named(key: NamedKey, modifiers: ModifiersState) -> Option<Action> {
        key_action(&Key::Named(key), modifiers)
    }

    const NONE: ModifiersState = ModifiersState::empty();
    const CTRL: ModifiersState = ModifiersState::CONTROL;
    const SHIFT: ModifiersState = ModifiersState::SHIFT;

    #[test]
    fn undo_redo_and_save_need_ctrl() {
        assert_eq!(press("z", CTRL), Some(Action::Undo));
        assert_eq!(press("Z", CTRL | SHIFT), Some(Action::Redo));
        assert_eq!(press("y", CTRL), Some(Action::Redo));
        assert_eq!(press("s", CTRL), Some(Action::SavePlan));
        // Without Ctrl, S is a screenshot and Z and Y do nothing; Ctrl with another key
        // does nothing either (Ctrl+Q is not Q).
        assert_eq!(press("s", NONE), Some(Action::Screenshot));
        assert_eq!(press("z", NONE), None);
        assert_eq!(press("y", NONE), None);
        assert_eq!(press("q", CTRL), None);
        assert_eq!(press("Q", SHIFT), Some(Action::Quit));
    }

    #[test]
    fn arrows_move_and_ctrl_arrows_turn_ten_times_with_shift() {
        assert_eq!(
            named(NamedKey::ArrowLeft, NONE),
            Some(Action::Nudge {
                along: ScreenAxis::Right,
                mm: -1.0
            })
        );
        assert_eq!(
            named(NamedKey::ArrowUp, SHIFT),
            Some(Action::Nudge {
                along: ScreenAxis::Up,
                mm: 10.0
            })
        );
        assert_eq!(
            named(NamedKey::ArrowRight, CTRL),
            Some(Action::Turn {
                about: ScreenAxis::Up,
                degrees: 1.0
            })
        );
        assert_eq!(
            named(NamedKey::ArrowDown, CTRL | SHIFT),
            Some(Action::Turn {
                about: ScreenAxis::Right,
                degrees: 10.0
            })
        );
        // + brings the mesh toward the eye (against the view direction), - takes it away.
        assert_eq!(
            press("+", SHIFT),
            Some(Action::Nudge {
                along: ScreenAxis::Forward,
                mm: -10.0
            })
        );
        assert_eq!(
            press("-", NONE),
            Some(Action::Nudge {
                along: ScreenAxis::Forward,
                mm: 1.0
            })
        );
    }

    #[test]
    fn a_held_key_repeats_moves_and_undo_but_no_toggle_save_or_quit() {
        for moves in [
            named(NamedKey::ArrowLeft, NONE),
            named(NamedKey::ArrowUp, CTRL),
            press("-", NONE),
            press("z", CTRL),
            press("y", CTRL),
        ] {
            assert!(moves.is_some_and(|a| a.repeats()), "{moves:?}");
        }
        for once in [
            press("v", NONE),
            press("s", NONE),
            press("s", CTRL),
            press("Q", SHIFT),
            press("h", NONE),
            named(NamedKey::Escape, NONE),
            named(NamedKey::Delete, NONE),
            named(NamedKey::F5, NONE),
        ] {
            assert!(once.is_some_and(|a| !a.repeats()), "{once:?}");
        }
    }

    #[test]
    fn digits_choose_the_orderings_of_the_help() {
        for (digit, ordering) in ORDERINGS {
            assert_eq!(press(digit, NONE), Some(Action::Ordering(ordering)));
        }
        assert_eq!(press("8", NONE), None);
        assert_eq!(press("0", NONE), None);
    }

    /// Every key the help lists as a single character does something.
    #[test]
    fn every_single_key_of_the_help_has_an_action() {
        for (keys, what) in super::KEYS {
            for key in keys.split([',', '/']).map(str::trim) {
                if key.chars().count() == 1 {
                    assert!(press(key, NONE).is_some(), "{key:?} ({what}) has no action");
                }
            }
        }
        for key in [
            NamedKey::Escape,
            NamedKey::F5,
            NamedKey::Tab,
            NamedKey::Delete,
        ] {
            assert!(named(key, NONE).is_some(), "{key:?}");
        }
        assert_eq!(named(NamedKey::Home, NONE), None);
    }
}
