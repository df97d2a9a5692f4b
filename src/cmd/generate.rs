//! `photopose generate man|completions SHELL --out DIR` (hidden): the man
//! pages and shell completions of this CLI, generated from its clap
//! definition at packaging time (`cargo deb` ships what this writes; the
//! generated files are not kept in the repository).

use anyhow::{Context, Result};
use clap::{CommandFactory, Parser, Subcommand};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Arguments of `photopose generate`.
#[derive(Parser, Debug)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Subcommand, Debug)]
enum What {
    /// Man pages: `photopose.1` and one `photopose-CMD.1` per subcommand.
    Man {
        /// Folder to write into (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
    /// The completion script of one shell.
    Completions {
        /// bash, zsh, fish, elvish or powershell.
        shell: clap_complete::Shell,
        /// Folder to write into (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    match args.what {
        What::Man { out } => {
            create(&out)?;
            let cli = crate::Cli::command();
            // Writes the page of the command and of every visible subcommand.
            clap_mangen::generate_to(cli, &out)
                .with_context(|| format!("cannot write the man pages into {}", out.display()))?;
            outln!("{}: man pages written", out.display())?;
        }
        What::Completions { shell, out } => {
            create(&out)?;
            let mut cli = crate::Cli::command();
            let path = clap_complete::generate_to(shell, &mut cli, "photopose", &out)
                .with_context(|| {
                    format!(
                        "cannot write the {shell} completions into {}",
                        out.display()
                    )
                })?;
            outln!("{}", path.display())?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn create(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("--out: cannot create {}", dir.display()))
}
