//! The README and every guide under `docs/` work as written: every command of their shell
//! blocks (```` ```sh ```` or a bare fence; ```` ```text ````, ```` ```json ```` and the like are
//! not run) is run in order, each page from an empty directory (with `calibration/` of the
//! repository beside it), as a new user would paste it. `omniwarp` and `cargo run --release --`
//! stand for the binary under test, `cargo run --release --example NAME` for the example built
//! with it; the daemon's `serve` is started in the background (on a free port, which the `curl`
//! lines then use in place of 7878); benchmarks are only checked to exist (`--help`), since
//! they time the machine for minutes and run on demand. The README's Rust block is the example
//! `examples/warp_image.rs`, word for word, so it compiles.

use std::io::BufRead;
use std::path::Path;
use std::process::{Child, Command, Stdio};

/// The fenced blocks of a Markdown page, each with its info string (`sh`, `rust`, or empty).
fn blocks(page: &str) -> Vec<(String, Vec<&str>)> {
    let mut out = Vec::new();
    let mut open: Option<(String, Vec<&str>)> = None;
    for line in page.lines() {
        let fence = line.trim_start().strip_prefix("```");
        match (fence, open.take()) {
            (Some(_), Some(block)) => out.push(block),
            (Some(info), None) => open = Some((info.trim().to_string(), Vec::new())),
            (None, Some(mut block)) => {
                block.1.push(line);
                open = Some(block);
            }
            (None, None) => {}
        }
    }
    out
}

/// The logical command lines of every shell block: continuation lines joined, trailing
/// comments (`  # …`) dropped.
fn commands(page: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut pending = String::new();
    let shell = blocks(page)
        .into_iter()
        .filter(|(info, _)| info.is_empty() || info == "sh");
    for line in shell.flat_map(|(_, lines)| lines) {
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

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Runs a page's commands from an empty directory; answers how many ran and how many
/// benchmarks were checked.
fn run_page(name: &str) -> (usize, usize) {
    let page = std::fs::read_to_string(root().join(name)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink(root().join("calibration"), dir.path().join("calibration")).unwrap();
    let examples = Path::new(&bin_dir()).join("examples");
    let mut daemon: Option<Daemon> = None;
    let (mut ran, mut checked) = (0, 0);
    for original in commands(&page) {
        let cmd = original
            .replace(
                "cargo run --release --example ",
                &format!("{}/", examples.display()),
            )
            .replace("cargo run --release --features bench --", "omniwarp")
            .replace("cargo run --release --", "omniwarp")
            .replace("./scripts/test", "");
        // The example's arguments follow `--`, which cargo needs and the binary does not.
        let cmd = cmd.replacen(" -- ", " ", usize::from(cmd.starts_with('/')));
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
                .unwrap_or_else(|| panic!("{name}: `{cmd}` printed `{first}`"))
                .to_string();
            daemon = Some(Daemon { child, addr });
            ran += 1;
            continue;
        }
        if words.first() == Some(&"omniwarp") && words.get(1) == Some(&"bench") {
            // Only `bench warp` is in the shipped command; a page that shows another benchmark
            // as `omniwarp bench …` gives its reader a command that does not exist.
            assert!(
                words.get(2) == Some(&"warp") || original.contains("--features bench"),
                "{name}: `{original}` needs `cargo run --release --features bench -- bench …`"
            );
            let out = shell(dir.path(), &format!("{} --help", words[..3].join(" ")));
            assert!(
                out.status.success(),
                "{name}: `{cmd}` is not a benchmark: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            checked += 1;
            continue;
        }
        let line = if cmd.starts_with("curl") {
            let d = daemon
                .as_ref()
                .unwrap_or_else(|| panic!("{name}: `{cmd}` comes before any `omniwarp serve`"));
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
                "{name}: `{cmd}`: {:?}\n{}{}",
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
            "{name}: `{cmd}` failed ({:?}):\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
        ran += 1;
    }
    eprintln!("{name}: {ran} commands run, {checked} benchmarks checked");
    (ran, checked)
}

#[test]
fn every_command_in_the_readme_runs_as_written() {
    let (ran, _) = run_page("README.md");
    assert!(ran >= 10, "{ran} run: the parser lost commands");
}

/// Every guide and reference page under `docs/`, each from its own empty directory.
#[test]
fn every_command_in_the_docs_runs_as_written() {
    let mut pages: Vec<String> = std::fs::read_dir(root().join("docs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".md"))
        .collect();
    pages.sort();
    let (mut ran, mut checked, mut with_commands) = (0, 0, 0);
    for page in &pages {
        let (r, c) = run_page(&format!("docs/{page}"));
        with_commands += usize::from(r + c > 0);
        (ran, checked) = (ran + r, checked + c);
    }
    assert!(
        ran > 60 && checked >= 8 && with_commands >= 8,
        "{ran} run and {checked} checked on {with_commands} of {} pages: the parser lost \
         commands",
        pages.len()
    );
}

/// The library example in the README is `examples/warp_image.rs` below its header comment,
/// which `cargo test` compiles.
#[test]
fn the_readmes_rust_example_is_a_compiled_example() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let rust: Vec<String> = blocks(&readme)
        .into_iter()
        .filter(|(info, _)| info == "rust")
        .map(|(_, lines)| lines.join("\n"))
        .collect();
    assert_eq!(rust.len(), 1, "the README has one Rust block");
    let example = std::fs::read_to_string(root().join("examples/warp_image.rs")).unwrap();
    let body: Vec<&str> = example
        .lines()
        .skip_while(|l| l.starts_with("//!") || l.is_empty())
        .collect();
    assert_eq!(rust[0].trim(), body.join("\n").trim());
}

#[test]
fn the_parser_joins_continuations_and_drops_comments() {
    let text = "x\n```\nomniwarp a \\\n    --b c   # note\ncurl -d '{\"a\": 1,\n  \"b\": 2}'  # c\n```\n\
                ```text\nomniwarp serve --bind 0.0.0.0:7878\n```\n```sh\nomniwarp d\n```\n";
    assert_eq!(
        commands(text),
        vec![
            "omniwarp a --b c".to_string(),
            "curl -d '{\"a\": 1, \"b\": 2}'".to_string(),
            "omniwarp d".to_string()
        ]
    );
}

/// The `--help` of every command, by command name.
fn helps() -> Vec<(String, String)> {
    let help = |args: &[&str]| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_omniwarp"))
            .args(args)
            .arg("--help")
            .output()
            .unwrap();
        String::from_utf8(out.stdout).unwrap()
    };
    let top = help(&[]);
    let names: Vec<String> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .filter(|n| n != "help")
        .collect();
    assert!(names.len() > 10, "{top}");
    names
        .into_iter()
        .map(|n| {
            let text = help(&[n.as_str()]);
            (n, text)
        })
        .collect()
}

/// Help that sends a user to `omniwarp X --flag` names a command and flag that exist (it once
/// sent them to `bench camera --out`, which does not).
#[test]
fn every_command_a_help_text_names_exists() {
    let helps = helps();
    let mut wrong = Vec::new();
    for (name, text) in &helps {
        // A help text wraps its lines: join them before looking for the quoted commands.
        let joined = text.split_whitespace().collect::<Vec<_>>().join(" ");
        for quoted in joined.split('`').skip(1).step_by(2) {
            let Some(rest) = quoted.strip_prefix("omniwarp ") else {
                continue;
            };
            let mut words = rest.split_whitespace();
            let command = words.next().unwrap_or_default();
            let Some((_, target)) = helps.iter().find(|(n, _)| n == command) else {
                wrong.push(format!("{name}: `{quoted}`: no command {command}"));
                continue;
            };
            for flag in words.filter(|w| w.starts_with("--")) {
                let flag = flag.split('=').next().unwrap();
                if !target.contains(&format!("{flag} ")) && !target.contains(&format!("{flag}\n")) {
                    wrong.push(format!("{name}: `{quoted}`: {command} has no {flag}"));
                }
            }
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}");
}
