//! The subcommands of the `photopose` binary, one module each.

pub mod defaults;
pub mod resect;
