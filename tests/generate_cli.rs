//! Packaging: the man pages and shell completions generated from the CLI
//! (`photopose generate`, hidden), as `packaging/deb.sh` makes them for
//! `cargo deb`; and the package metadata names every file it ships (the
//! unit and the `photopose` user's sysusers file come from the
//! `unit-scripts` folder).

mod common;

use common::{bin, root, scratch};

#[test]
fn man_pages_and_completions_are_generated_from_the_cli() {
    let dir = scratch("generate");
    let man = dir.join("man");
    let o = bin()
        .args(["generate", "man", "--out"])
        .arg(&man)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let page = std::fs::read_to_string(man.join("photopose.1")).unwrap();
    assert!(
        page.starts_with(".ie") || page.contains(".TH photopose 1"),
        "{page}"
    );
    assert!(
        page.contains("photopose\\-run"),
        "subcommands listed: {page}"
    );
    for sub in ["run", "check-config", "camera", "calibrate", "rsi-sim"] {
        let p = man.join(format!("photopose-{sub}.1"));
        assert!(p.is_file(), "{} missing", p.display());
    }
    assert!(
        !man.join("photopose-generate.1").exists(),
        "generate is hidden"
    );
    let completions = dir.join("completions");
    for (shell, file, marker) in [
        ("bash", "photopose.bash", "complete -F"),
        ("zsh", "_photopose", "#compdef photopose"),
        ("fish", "photopose.fish", "complete -c photopose"),
    ] {
        let o = bin()
            .args(["generate", "completions", shell, "--out"])
            .arg(&completions)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let script = std::fs::read_to_string(completions.join(file)).unwrap();
        assert!(script.contains(marker), "{shell}: {script}");
        assert!(
            script.contains("check-config"),
            "{shell} knows the subcommands"
        );
    }
}

#[test]
fn the_package_ships_binary_unit_config_user_docs_man_pages_and_completions() {
    let manifest: toml::Table = std::fs::read_to_string(root().join("Cargo.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let deb = &manifest["package"]["metadata"]["deb"];
    let assets: Vec<(String, String)> = deb["assets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| {
            let a = a.as_array().unwrap();
            (a[0].as_str().unwrap().into(), a[1].as_str().unwrap().into())
        })
        .collect();
    for want in [
        "usr/bin/",
        "etc/photopose/photopose.toml",
        "etc/photopose/camera.toml",
        "etc/photopose/plate.csv",
        "usr/share/doc/photopose/README.md",
        "usr/share/man/man1/",
        "usr/share/bash-completion/completions/photopose",
        "usr/share/zsh/vendor-completions/_photopose",
        "usr/share/fish/vendor_completions.d/photopose.fish",
    ] {
        assert!(
            assets.iter().any(|(_, to)| to == want),
            "{want} not shipped"
        );
    }
    // Every source that is not built at packaging time exists.
    for (from, _) in &assets {
        if from.starts_with("target/") || from.contains('*') {
            continue;
        }
        assert!(root().join(from).is_file(), "{from} missing");
    }
    let unit = std::fs::read_to_string(root().join("systemd/photopose.service")).unwrap();
    assert!(unit.contains("ExecStart=/usr/bin/photopose run"), "{unit}");
    assert!(unit.contains("User=photopose"));
    let sysusers = std::fs::read_to_string(root().join("systemd/photopose.sysusers")).unwrap();
    assert!(
        sysusers.lines().any(|l| l.starts_with("u photopose ")),
        "{sysusers}"
    );
    assert_eq!(
        deb["systemd-units"]["unit-name"].as_str(),
        Some("photopose")
    );
}
