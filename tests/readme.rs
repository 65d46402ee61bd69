//! The README works as written: every command of its code blocks is run, in order, in a fresh
//! directory (with `calibration/` of the repository beside it), as a new user would paste it.
//! `omniwarp` and `cargo run --release --` stand for the binary under test; the daemon's
//! `serve` is started in the background (on a free port, which the `curl` lines then use in
//! place of 7878); benchmarks are only checked to exist (`--help`), since they time the machine
//! for minutes and run on demand.

use std::io::BufRead;
use std::path::Path;
use std::process::{Child, Command, Stdio};

/// The logical command lines of every fenced block: continuation lines joined, trailing
/// comments (`  # …`) dropped.
fn commands(readme: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_block = false;
    let mut pending = String::new();
    for line in readme.lines() {
        if line.trim_start().starts_with("```") {
            in_block = !in_block;
            continue;
        }
        if !in_block {
            continue;
        }
        let code = match line.find("  # ") {
            Some(i) => &line[..i],
            None => line,
        };
        let code = code.trim_end();
        if let Some(head) = code.strip_suffix('\\') {
            pending.push_str(head.trim_end());
            pending.push(' ');
            continue;
        }
        pending.push_str(code.trim_start());
        // A quoted argument (a JSON body) may run over several lines.
        if pending.matches('\'').count() % 2 == 1 {
            pending.push(' ');
            continue;
        }
        let cmd = std::mem::take(&mut pending);
        if !cmd.trim().is_empty() {
            out.push(cmd.trim().to_string());
        }
    }
    out
}

struct Daemon {
    child: Child,
    addr: String,
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn shell(dir: &Path, line: &str) -> std::process::Output {
    Command::new("sh")
        .arg("-c")
        .arg(line)
        .current_dir(dir)
        .env(
            "PATH",
            format!(
                "{}:{}",
                bin_dir(),
                std::env::var("PATH").unwrap_or_default()
            ),
        )
        .output()
        .unwrap()
}

fn bin_dir() -> String {
    Path::new(env!("CARGO_BIN_EXE_omniwarp"))
        .parent()
        .unwrap()
        .to_string_lossy()
        .into_owned()
}

#[test]
fn every_command_in_the_readme_runs_as_written() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink(root.join("calibration"), dir.path().join("calibration")).unwrap();
    let mut daemon: Option<Daemon> = None;
    let (mut ran, mut checked) = (0, 0);
    for cmd in commands(&readme) {
        let cmd = cmd
            .replace("cargo run --release --", "omniwarp")
            .replace("./scripts/test", "");
        let cmd = cmd.trim();
        if cmd.is_empty() {
            continue;
        }
        let words: Vec<&str> = cmd.split_whitespace().collect();
        if words.first() == Some(&"omniwarp") && words.get(1) == Some(&"serve") {
            // A second daemon would only repeat the first; the walkthrough uses the one with
            // a data directory, so that one replaces an earlier one.
            drop(daemon.take());
            let mut child = Command::new(env!("CARGO_BIN_EXE_omniwarp"))
                .args(&words[1..])
                .args(["--bind", "127.0.0.1:0"])
                .current_dir(dir.path())
                .stdout(Stdio::piped())
                .stderr(Stdio::null())
                .spawn()
                .unwrap();
            let mut first = String::new();
            std::io::BufReader::new(child.stdout.take().unwrap())
                .read_line(&mut first)
                .unwrap();
            let addr = first
                .trim()
                .strip_prefix("listening on http://")
                .unwrap_or_else(|| panic!("`{cmd}` printed `{first}`"))
                .to_string();
            daemon = Some(Daemon { child, addr });
            ran += 1;
            continue;
        }
        if words.first() == Some(&"omniwarp") && words.get(1) == Some(&"bench") {
            let out = shell(dir.path(), &format!("{} --help", words[..3].join(" ")));
            assert!(
                out.status.success(),
                "`{cmd}` is not a benchmark: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            checked += 1;
            continue;
        }
        let line = if cmd.starts_with("curl") {
            let d = daemon
                .as_ref()
                .unwrap_or_else(|| panic!("`{cmd}` comes before any `omniwarp serve`"));
            let streaming = cmd.contains(" -N ");
            let mut line = cmd.replace("localhost:7878", &d.addr);
            // The change feed never ends: one second of it is enough.
            line = line.replacen(
                "curl",
                if streaming {
                    "curl --max-time 1"
                } else {
                    "curl --fail-with-body"
                },
                1,
            );
            let out = shell(dir.path(), &line);
            let ok = out.status.success() || (streaming && out.status.code() == Some(28));
            assert!(
                ok && (!streaming
                    || String::from_utf8_lossy(&out.stdout).contains("event: change")),
                "`{cmd}`: {:?}\n{}{}",
                out.status,
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            ran += 1;
            continue;
        } else {
            cmd.to_string()
        };
        let out = shell(dir.path(), &line);
        assert!(
            out.status.success(),
            "`{cmd}` failed ({:?}):\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
        ran += 1;
    }
    eprintln!("README: {ran} commands run, {checked} benchmarks checked");
    assert!(
        ran > 30 && checked >= 6,
        "{ran} run, {checked} checked: the parser lost commands"
    );
}

#[test]
fn the_parser_joins_continuations_and_drops_comments() {
    let text =
        "x\n```\nomniwarp a \\\n    --b c   # note\ncurl -d '{\"a\": 1,\n  \"b\": 2}'  # c\n```\n";
    assert_eq!(
        commands(text),
        vec![
            "omniwarp a --b c".to_string(),
            "curl -d '{\"a\": 1, \"b\": 2}'".to_string()
        ]
    );
}
