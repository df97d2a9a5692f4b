//! photopose-field: the test field that defines the object frame.
//!
//! Owns the target model, the test-field CSV format of `docs/conventions.md`, the
//! coded-target numbering of `docs/coded-targets.md` and the design of plates.
//! Invariant: no IO; parsing works on text handed in by the caller.

pub mod codes;
pub mod design;
pub mod field;

pub use field::{Field, FieldError, Target, TargetKind};
