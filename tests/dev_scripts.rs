//! The contributor scripts (dev/*.sh, .ci/run) parse: a quoting slip in a script that only runs on a
//! GPU machine is otherwise found there, after the build and the transfer.

use std::path::Path;
use std::process::Command;

#[test]
fn every_dev_script_parses() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let Ok(dev) = std::fs::read_dir(root.join("dev")) else {
        // The published package leaves the contributor scripts out.
        println!("skipped: no dev/ here (a packaged crate)");
        return;
    };
    let mut scripts: Vec<_> = dev
        .map(|entry| entry.expect("dev/ is readable").path())
        .filter(|path| path.extension().is_some_and(|ext| ext == "sh"))
        .collect();
    scripts.push(root.join(".ci/run"));
    assert!(scripts.len() >= 3, "dev/ lost its scripts: {scripts:?}");
    let Ok(version) = Command::new("bash").arg("--version").output() else {
        println!("skipped: bash not found");
        return;
    };
    assert!(version.status.success());
    for script in scripts {
        let out = Command::new("bash")
            .arg("-n")
            .arg(&script)
            .output()
            .expect("bash runs");
        assert!(
            out.status.success(),
            "{} does not parse: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}
