//! Helpers shared by the end-to-end tests (building QEMU images, running them, decoding output).
//!
//! The firmware images live in `tests/qemu` (crate `ferrosid-qemu`, excluded from the host
//! workspace). [`build_images`] builds them for `thumbv7em-none-eabihf` with a dedicated target
//! directory (`<repo>/target/qemu`), so the nested cargo never waits on the lock that the outer
//! `cargo test` holds on the workspace target directory. [`run_qemu`] runs one image on
//! `qemu-system-arm -machine mps2-an386 -cpu cortex-m4` under `timeout`, and [`decode_defmt`]
//! turns the binary defmt frames the image wrote to semihosting stdout into text lines, in
//! process, with `defmt-decoder` and the table embedded in the image's ELF.
//!
//! Every failure is an [`Error`] naming what went wrong and what to do; missing tools point at
//! `scripts/setup.sh`.

use std::ffi::OsString;
use std::fmt;
use std::io;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

pub mod closedloop;
pub mod e2e;

/// Target triple of the firmware images (Cortex-M4F with hardware floating point).
pub const TARGET: &str = "thumbv7em-none-eabihf";

/// Errors of the QEMU harness.
#[derive(Debug)]
pub enum Error {
    /// A required host tool is missing; the message says how to install it.
    ToolMissing {
        /// Program that could not be started.
        tool: String,
        /// What to do about it.
        hint: String,
    },
    /// Starting or talking to a child process failed.
    Io {
        /// What was being done.
        context: String,
        /// Underlying error.
        source: io::Error,
    },
    /// `cargo build` of the firmware images failed.
    Build {
        /// Command line that failed.
        command: String,
        /// Cargo's stderr (tail).
        stderr: String,
    },
    /// QEMU did not finish within the time limit.
    Timeout {
        /// Image that was running.
        elf: PathBuf,
        /// Limit that was exceeded.
        limit: Duration,
        /// Whatever the image printed on stderr.
        stderr: String,
    },
    /// QEMU was killed by a signal or ended without an exit status.
    NoExitStatus {
        /// Image that was running.
        elf: PathBuf,
        /// QEMU's stderr.
        stderr: String,
    },
    /// The ELF has no defmt table, or the stream holds a malformed frame.
    Defmt {
        /// Image whose output was decoded.
        elf: PathBuf,
        /// What is wrong.
        message: String,
    },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::ToolMissing { tool, hint } => write!(f, "`{tool}` is not available: {hint}"),
            Error::Io { context, source } => write!(f, "{context}: {source}"),
            Error::Build { command, stderr } => {
                write!(f, "firmware build failed: `{command}`\n{stderr}")
            }
            Error::Timeout { elf, limit, stderr } => write!(
                f,
                "QEMU running {} did not exit within {} s (stderr: {stderr})",
                elf.display(),
                limit.as_secs()
            ),
            Error::NoExitStatus { elf, stderr } => write!(
                f,
                "QEMU running {} ended without an exit status (killed by a signal?); stderr: {stderr}",
                elf.display()
            ),
            Error::Defmt { elf, message } => {
                write!(f, "defmt decoding of {} failed: {message}", elf.display())
            }
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

const SETUP_HINT: &str = "run scripts/setup.sh (installs the thumbv7em-none-eabihf target, \
                          qemu-system-arm and the LLVM tools llvm-size, llvm-objdump and \
                          llvm-symbolizer)";

/// Root of the ferrosid repository (parent of this crate's directory).
pub fn repo_root() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest.parent().unwrap_or(manifest).to_path_buf()
}

/// Manifest of the firmware image crate.
pub fn image_manifest() -> PathBuf {
    repo_root().join("tests").join("qemu").join("Cargo.toml")
}

/// Target directory of the firmware image builds (`<repo>/target/qemu`), separate from the
/// workspace target directory so the nested cargo does not wait on the outer cargo's lock.
pub fn image_target_dir() -> PathBuf {
    repo_root().join("target").join("qemu")
}

/// Builds bin `bin` of the image crate (feature of the same name) in release around the
/// generated module `module`, handed over in the environment variable `model_env`, in
/// `target_dir` (one directory per variant so builds never overwrite each other); returns the
/// ELF. The outer cargo's target and flags are cleared so the nested build targets the M4F.
pub fn build_model_image(bin: &str, model_env: &str, module: &Path, target_dir: &Path) -> PathBuf {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = std::process::Command::new(cargo);
    cmd.args([
        "build",
        "--release",
        "--target",
        TARGET,
        "--features",
        bin,
        "--bin",
        bin,
    ])
    .arg("--manifest-path")
    .arg(image_manifest());
    scrub_cargo_env(&mut cmd);
    cmd.env("CARGO_TARGET_DIR", target_dir)
        .env("DEFMT_LOG", "info")
        .env(model_env, module)
        .stdin(std::process::Stdio::null());
    let out = cmd.output().expect("start cargo");
    assert!(
        out.status.success(),
        "building the {bin} image failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    target_dir.join(TARGET).join("release").join(bin)
}

/// The number after `key=` in a whitespace-separated log line (panics naming the key).
pub fn log_field(text: &str, key: &str) -> f64 {
    text.split_whitespace()
        .find_map(|w| w.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key}= in {text:?}"))
}

/// Path of the release ELF of image `bin` (after [`build_images`]).
pub fn image_path(bin: &str) -> PathBuf {
    image_target_dir().join(TARGET).join("release").join(bin)
}

/// Builds the release images `bins` of `tests/qemu` for [`TARGET`] with `DEFMT_LOG=info` and
/// returns their ELF paths in the same order.
///
/// Environment that the outer cargo or the user may have set for host builds (target dir,
/// build target, rustflags) is removed so it cannot leak into the firmware build.
pub fn build_images(bins: &[&str]) -> Result<Vec<PathBuf>, Error> {
    let cargo: OsString = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(&cargo);
    cmd.arg("build")
        .arg("--release")
        .arg("--target")
        .arg(TARGET)
        .arg("--manifest-path")
        .arg(image_manifest());
    for bin in bins {
        cmd.arg("--bin").arg(bin);
    }
    scrub_cargo_env(&mut cmd);
    cmd.env("CARGO_TARGET_DIR", image_target_dir())
        .env("DEFMT_LOG", "info")
        .stdin(Stdio::null());
    let command = format!("{cmd:?}");
    let out = cmd.output().map_err(|source| match source.kind() {
        io::ErrorKind::NotFound => Error::ToolMissing {
            tool: cargo.to_string_lossy().into_owned(),
            hint: "install the Rust toolchain (rustup) first".into(),
        },
        _ => Error::Io {
            context: format!("starting {command}"),
            source,
        },
    })?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        let hint = if stderr.contains("may not be installed")
            || stderr.contains("can't find crate for `core`")
        {
            format!("\nhint: the {TARGET} target is missing: {SETUP_HINT}")
        } else {
            String::new()
        };
        return Err(Error::Build {
            command,
            stderr: format!("{}{hint}", tail(&stderr, 60)),
        });
    }
    Ok(bins.iter().map(|b| image_path(b)).collect())
}

/// Last `n` lines of `text`.
fn tail(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

/// How to run an image.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Words passed on the semihosting command line (after the program name `image`).
    pub args: Vec<String>,
    /// Run with `-icount shift=0` (one instruction per virtual nanosecond: deterministic
    /// SysTick-based instruction counts).
    pub icount: bool,
    /// Wall-clock limit, enforced with coreutils `timeout` (QEMU is killed after it).
    pub timeout: Duration,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            args: Vec::new(),
            icount: false,
            timeout: Duration::from_secs(120),
        }
    }
}

/// Result of one QEMU run that ended with an exit status.
#[derive(Debug, Clone)]
pub struct QemuRun {
    /// QEMU's exit status: the image's semihosting exit code (0 pass, 1 check failed,
    /// 101 panic), or QEMU's own error status.
    pub exit_code: i32,
    /// Raw semihosting stdout: binary defmt frames.
    pub stdout: Vec<u8>,
    /// Semihosting stderr (panic locations) and QEMU's own diagnostics.
    pub stderr: String,
}

/// Checks that `qemu-system-arm` can be started.
pub fn require_qemu() -> Result<(), Error> {
    match Command::new("qemu-system-arm")
        .arg("--version")
        .stdin(Stdio::null())
        .output()
    {
        Ok(out) if out.status.success() => Ok(()),
        Ok(out) => Err(Error::ToolMissing {
            tool: "qemu-system-arm".into(),
            hint: format!(
                "`qemu-system-arm --version` failed ({}); {SETUP_HINT}",
                out.status
            ),
        }),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Err(Error::ToolMissing {
            tool: "qemu-system-arm".into(),
            hint: format!("not found on PATH; {SETUP_HINT}"),
        }),
        Err(source) => Err(Error::Io {
            context: "starting qemu-system-arm --version".into(),
            source,
        }),
    }
}

/// Runs `elf` on `qemu-system-arm -machine mps2-an386 -cpu cortex-m4` with semihosting, under
/// coreutils `timeout`, and returns its exit status and output. The caller checks the status.
pub fn run_qemu(elf: &Path, opts: &RunOptions) -> Result<QemuRun, Error> {
    require_qemu()?;
    let mut semihosting = String::from("enable=on,target=native,arg=image");
    for a in &opts.args {
        // QEMU option syntax: a comma inside a value is escaped by doubling it.
        semihosting.push_str(",arg=");
        semihosting.push_str(&a.replace(',', ",,"));
    }
    let mut cmd = Command::new("timeout");
    cmd.arg("--kill-after=5")
        .arg(opts.timeout.as_secs().max(1).to_string())
        .arg("qemu-system-arm")
        .args(["-machine", "mps2-an386", "-cpu", "cortex-m4", "-nographic"])
        .args(["-monitor", "none", "-serial", "none"])
        .arg("-semihosting-config")
        .arg(&semihosting);
    if opts.icount {
        cmd.args(["-icount", "shift=0"]);
    }
    cmd.arg("-kernel").arg(elf).stdin(Stdio::null());
    let out = cmd.output().map_err(|source| match source.kind() {
        io::ErrorKind::NotFound => Error::ToolMissing {
            tool: "timeout".into(),
            hint: "install coreutils".into(),
        },
        _ => Error::Io {
            context: format!("starting {cmd:?}"),
            source,
        },
    })?;
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    match out.status.code() {
        // coreutils timeout: 124 = limit reached, 137 = had to SIGKILL after --kill-after.
        Some(124) | Some(137) => Err(Error::Timeout {
            elf: elf.to_path_buf(),
            limit: opts.timeout,
            stderr,
        }),
        Some(code) => Ok(QemuRun {
            exit_code: code,
            stdout: out.stdout,
            stderr,
        }),
        None => Err(Error::NoExitStatus {
            elf: elf.to_path_buf(),
            stderr,
        }),
    }
}

/// One decoded defmt log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogLine {
    /// Log level (`"INFO"`, `"ERROR"`, ...), `None` for `defmt::println!`.
    pub level: Option<String>,
    /// Formatted message.
    pub text: String,
}

impl fmt::Display for LogLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.level {
            Some(l) => write!(f, "{l:<5} {}", self.text),
            None => f.write_str(&self.text),
        }
    }
}

/// Decodes the defmt frames in `stdout` with the table of `elf`. A frame cut off at the end of
/// the stream (image stopped mid-frame) is ignored; a malformed frame is an error.
pub fn decode_defmt(elf: &Path, stdout: &[u8]) -> Result<Vec<LogLine>, Error> {
    let bytes = std::fs::read(elf).map_err(|source| Error::Io {
        context: format!("reading {}", elf.display()),
        source,
    })?;
    let defmt_err = |message: String| Error::Defmt {
        elf: elf.to_path_buf(),
        message,
    };
    let table = defmt_decoder::Table::parse(&bytes)
        .map_err(|e| defmt_err(format!("cannot read the defmt table: {e}")))?
        .ok_or_else(|| defmt_err("the ELF has no .defmt section".into()))?;
    let mut decoder = table.new_stream_decoder();
    decoder.received(stdout);
    let mut lines = Vec::new();
    loop {
        match decoder.decode() {
            Ok(frame) => lines.push(LogLine {
                level: frame.level().map(|l| l.as_str().to_uppercase()),
                text: frame.display_message().to_string(),
            }),
            Err(defmt_decoder::DecodeError::UnexpectedEof) => break,
            Err(defmt_decoder::DecodeError::Malformed) => {
                return Err(defmt_err(format!(
                    "malformed frame after {} decoded lines (last: {:?})",
                    lines.len(),
                    lines.last().map(|l: &LogLine| l.text.clone())
                )))
            }
        }
    }
    Ok(lines)
}

/// Builds image `bin`, runs it and decodes its log: the common path of the tests.
pub fn build_run_decode(bin: &str, opts: &RunOptions) -> Result<(QemuRun, Vec<LogLine>), Error> {
    require_qemu()?;
    let elf = build_images(&[bin])?.remove(0);
    let run = run_qemu(&elf, opts)?;
    let lines = decode_defmt(&elf, &run.stdout)?;
    Ok((run, lines))
}

/// A call or branch to a panic entry point in an image, with the source frames (innermost
/// first, inlined frames included) that debug information attributes to that instruction.
#[derive(Debug, Clone)]
pub struct PanicSite {
    /// Address of the branch instruction.
    pub addr: u64,
    /// Demangled name of the function containing it.
    pub function: String,
    /// Demangled name of the panic entry point it branches to.
    pub target: String,
    /// `(function, file:line:column)` frames from `llvm-symbolizer -i`, innermost first.
    pub frames: Vec<(String, String)>,
}

impl PanicSite {
    /// `true` when one of the frames lies in a file whose path contains `path_part`.
    pub fn has_frame_in(&self, path_part: &str) -> bool {
        self.frames.iter().any(|(_, loc)| loc.contains(path_part))
    }
}

impl fmt::Display for PanicSite {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:#x} in {} -> {}",
            self.addr, self.function, self.target
        )?;
        for (func, loc) in &self.frames {
            write!(f, "\n    {func} at {loc}")?;
        }
        Ok(())
    }
}

/// `true` for the names of functions that only panic: `core::panicking::*`, the panic handler,
/// and core's out-of-line failure paths (`slice_index_fail`, `unwrap_failed`, ...).
fn is_panic_entry(name: &str) -> bool {
    name.starts_with("core::panicking::")
        || name.ends_with("rust_begin_unwind")
        || (name.starts_with("core::")
            && (name.contains("panic") || name.ends_with("_fail") || name.ends_with("_failed")))
}

fn run_tool(tool: &str, args: &[&std::ffi::OsStr], stdin: Option<&str>) -> Result<String, Error> {
    use std::io::Write as _;
    let mut cmd = Command::new(tool);
    cmd.args(args).stdout(Stdio::piped()).stderr(Stdio::piped());
    cmd.stdin(if stdin.is_some() {
        Stdio::piped()
    } else {
        Stdio::null()
    });
    let mut child = cmd.spawn().map_err(|source| match source.kind() {
        io::ErrorKind::NotFound => Error::ToolMissing {
            tool: tool.into(),
            hint: format!("not found on PATH; {SETUP_HINT}"),
        },
        _ => Error::Io {
            context: format!("starting {tool}"),
            source,
        },
    })?;
    if let (Some(text), Some(mut pipe)) = (stdin, child.stdin.take()) {
        pipe.write_all(text.as_bytes())
            .map_err(|source| Error::Io {
                context: format!("writing to {tool}"),
                source,
            })?;
    }
    let out = child.wait_with_output().map_err(|source| Error::Io {
        context: format!("waiting for {tool}"),
        source,
    })?;
    if !out.status.success() {
        return Err(Error::Build {
            command: format!("{tool} {args:?}"),
            stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        });
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The panic sites of `elf` ([`panic_sites`]) whose innermost frame outside the standard
/// library lies in a file whose path contains one of `ours`, as display strings (the scans
/// assert this is empty; sites inside dependencies are not ours to fix).
pub fn our_panic_sites(elf: &Path, ours: &[&str]) -> Result<Vec<String>, Error> {
    Ok(panic_sites(elf)?
        .iter()
        .filter(|s| {
            let loc = s
                .frames
                .iter()
                .find(|(_, loc)| !loc.starts_with("/rustc/"))
                .map_or("", |(_, loc)| loc.as_str());
            ours.iter().any(|o| loc.contains(o))
        })
        .map(|s| s.to_string())
        .collect())
}

/// Every branch to a panic entry point in `elf` (from `llvm-objdump -d -C`), each attributed to
/// its source frames with `llvm-symbolizer -i` (the images carry full debug information).
pub fn panic_sites(elf: &Path) -> Result<Vec<PanicSite>, Error> {
    let dis = run_tool(
        "llvm-objdump",
        &[
            "-d".as_ref(),
            "-C".as_ref(),
            "--no-show-raw-insn".as_ref(),
            elf.as_os_str(),
        ],
        None,
    )?;
    let mut sites = Vec::new();
    let mut function = String::new();
    for line in dis.lines() {
        // Function label: `000012ab <name>:`; `$t`/`$d` are ARM mapping symbols, not functions.
        if line.ends_with(">:") {
            if let Some((_, name)) = line.split_once(" <") {
                let name = name.trim_end_matches(">:");
                if !name.starts_with('$') {
                    function = name.to_string();
                }
            }
            continue;
        }
        // Instruction: `    12ae:  \tbl\t0x3456 <target> @ imm = ...`.
        let Some((addr, rest)) = line.trim_start().split_once(':') else {
            continue;
        };
        let Ok(addr) = u64::from_str_radix(addr.trim(), 16) else {
            continue;
        };
        let mut words = rest.split_whitespace();
        let Some(op) = words.next() else { continue };
        if !op.starts_with('b') {
            continue;
        }
        let Some(target) = rest
            .split_once('<')
            .and_then(|(_, t)| t.split_once('>'))
            .map(|(t, _)| t.split('+').next().unwrap_or(t).to_string())
        else {
            continue;
        };
        if is_panic_entry(&target) && !is_panic_entry(&function) {
            sites.push(PanicSite {
                addr,
                function: function.clone(),
                target,
                frames: Vec::new(),
            });
        }
    }
    if sites.is_empty() {
        return Ok(sites);
    }
    let addrs: String = sites.iter().map(|s| format!("{:#x}\n", s.addr)).collect();
    let obj = format!("--obj={}", elf.display());
    let sym = run_tool(
        "llvm-symbolizer",
        &["-i".as_ref(), "-C".as_ref(), obj.as_ref()],
        Some(&addrs),
    )?;
    // One block per address: lines `function`, `file:line:col`, ..., then a blank line.
    for (site, block) in sites.iter_mut().zip(sym.split("\n\n")) {
        let lines: Vec<&str> = block.lines().filter(|l| !l.is_empty()).collect();
        site.frames = lines
            .chunks(2)
            .map(|c| {
                (
                    c[0].to_string(),
                    c.get(1).copied().unwrap_or("").to_string(),
                )
            })
            .collect();
    }
    Ok(sites)
}

/// Sizes of an ELF's allocated sections as `llvm-size -A` reports them, in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ImageSize {
    /// Code and read-only data in flash: `.vector_table`, `.text`, `.rodata`.
    pub text: u64,
    /// Initialised statics: stored in flash, copied to RAM at reset.
    pub data: u64,
    /// Zero-initialised (`.bss`) and uninitialised (`.uninit`) statics in RAM.
    pub bss: u64,
}

impl ImageSize {
    /// Flash use: `text + data`.
    pub fn flash(&self) -> u64 {
        self.text + self.data
    }
    /// Static RAM use: `data + bss` (the stack, which cortex-m-rt places at the top of RAM
    /// outside any section, is not included).
    pub fn ram(&self) -> u64 {
        self.data + self.bss
    }
}

/// Measures `elf` with `llvm-size -A` (SysV format: one line per section).
pub fn image_size(elf: &Path) -> Result<ImageSize, Error> {
    let out = Command::new("llvm-size")
        .arg("-A")
        .arg(elf)
        .stdin(Stdio::null())
        .output()
        .map_err(|source| match source.kind() {
            io::ErrorKind::NotFound => Error::ToolMissing {
                tool: "llvm-size".into(),
                hint: format!("not found on PATH; {SETUP_HINT}"),
            },
            _ => Error::Io {
                context: "starting llvm-size".into(),
                source,
            },
        })?;
    if !out.status.success() {
        return Err(Error::Build {
            command: format!("llvm-size -A {}", elf.display()),
            stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        });
    }
    Ok(parse_size_sysv(&String::from_utf8_lossy(&out.stdout)))
}

/// Parses `llvm-size -A` output: `.vector_table`, `.text`, `.rodata` count as text; `.data` as
/// data; `.bss` and `.uninit` as bss. Debug and defmt (non-allocated) sections are ignored.
pub fn parse_size_sysv(text: &str) -> ImageSize {
    let mut size = ImageSize::default();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        let (Some(name), Some(bytes)) = (it.next(), it.next()) else {
            continue;
        };
        let Ok(bytes) = bytes.parse::<u64>() else {
            continue;
        };
        match name {
            ".vector_table" | ".text" | ".rodata" => size.text += bytes,
            ".data" => size.data += bytes,
            ".bss" | ".uninit" => size.bss += bytes,
            _ => {}
        }
    }
    size
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sysv_size_sums_sections() {
        let text = "selftest  :\nsection            size        addr\n.vector_table       1024           0\n\
                    .text              20000        1024\n.rodata             3000       21024\n\
                    .data                 16   536870912\n.gnu.sgstubs           0       24040\n\
                    .bss               25000   536870928\n.uninit                0   536895928\n\
                    .defmt                 6           0\n.debug_info       100000           0\n\
                    Total             149046\n";
        let s = parse_size_sysv(text);
        assert_eq!(s.text, 24024);
        assert_eq!(s.data, 16);
        assert_eq!(s.bss, 25000);
        assert_eq!(s.flash(), 24040);
        assert_eq!(s.ram(), 25016);
    }
}

/// Removes the host build's target and rustflags variables from `cmd`, a cargo build of a
/// thumbv7em image (they would redirect or break it).
pub fn scrub_cargo_env(cmd: &mut std::process::Command) {
    for var in [
        "CARGO_BUILD_TARGET",
        "CARGO_BUILD_RUSTFLAGS",
        "RUSTFLAGS",
        "CARGO_ENCODED_RUSTFLAGS",
        "CARGO_TARGET_DIR",
        "CARGO_BUILD_TARGET_DIR",
    ] {
        cmd.env_remove(var);
    }
}

/// The firmware performance document (relative to the repository root) whose figures the bench
/// report and `tests/tests/qemu_images.rs` check against the measurement.
pub const PERFORMANCE_DOC: &str = "docs/firmware-performance.md";

/// One figure of the performance document: a table row
/// `` | `name` | value unit | ± noise | command | ``.
#[derive(Debug, Clone, PartialEq)]
pub struct DocumentedFigure {
    /// Name as the bench prints it (`BENCH <name> ...`), or `sizeprobe_ram_bytes` /
    /// `sizeprobe_flash_bytes`.
    pub name: String,
    /// The documented value.
    pub value: f64,
    /// Largest accepted difference from the measured value.
    pub noise: f64,
}

/// Parses the figure rows of the performance document: table rows whose first cell is a name
/// in backticks, second cell a number (thousands separators `,` allowed) and third cell
/// `± number`. Other lines are ignored.
pub fn documented_figures(doc: &str) -> Vec<DocumentedFigure> {
    fn number(cell: &str) -> Option<f64> {
        let t: String = cell
            .trim()
            .trim_start_matches('±')
            .trim()
            .split_whitespace()
            .next()?
            .chars()
            .filter(|c| *c != ',')
            .collect();
        t.parse().ok()
    }
    doc.lines()
        .filter_map(|line| {
            let cells: Vec<&str> = line.trim().strip_prefix('|')?.split('|').collect();
            if cells.len() < 4 || !cells[2].trim().starts_with('±') {
                return None;
            }
            let name = cells[0].trim().strip_prefix('`')?.strip_suffix('`')?;
            Some(DocumentedFigure {
                name: name.to_string(),
                value: number(cells[1])?,
                noise: number(cells[2])?,
            })
        })
        .collect()
}

#[cfg(test)]
mod doc_tests {
    use super::*;

    #[test]
    fn documented_figures_are_parsed_from_table_rows() {
        let doc = "| Figure | Value | Noise | Command |\n|---|---|---|---|\n\
                   | `welch_push_n1024` | 195.9 instr/sample | ± 0.1 | `scripts/bench-firmware.sh` |\n\
                   | `welch_push_max_n1024` | 3,560 instr/push | ± 40 | x |\n\
                   | not a figure | 1 | ± 1 | x |\n";
        let f = documented_figures(doc);
        assert_eq!(f.len(), 2);
        assert_eq!(f[0].name, "welch_push_n1024");
        assert_eq!((f[0].value, f[0].noise), (195.9, 0.1));
        assert_eq!((f[1].value, f[1].noise), (3560.0, 40.0));
    }
}
