//! Reads QEMU's `-d in_asm,exec,nochain` log of a firmware run from stdin and prints the
//! instructions executed per function of the ELF: each translated block's instruction count
//! (from `in_asm`) times its executions (from `exec`), summed per symbol of `arm-none-eabi-nm`.
//!
//!     gpmm-qemu-profile ELF [--top N] [--json] < qemu.log
//!
//! The table (or JSON with `--json`) lists the functions by instructions, with their share of
//! the run; `firmware-sim/profile.sh` runs the firmware under QEMU and pipes its log here.

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::process::{Command, ExitCode};

/// The options: the ELF, how many functions to list, JSON or a table.
struct Options {
    elf: String,
    top: usize,
    json: bool,
}

fn options() -> Result<Options, String> {
    let mut args = std::env::args().skip(1);
    let (mut elf, mut top, mut json) = (None, 30, false);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--top" => top = args.next().and_then(|n| n.parse().ok()).ok_or("--top needs a number")?,
            "--json" => json = true,
            "-h" | "--help" => return Err(String::new()),
            _ if elf.is_none() => elf = Some(a),
            _ => return Err(format!("unexpected argument {a}")),
        }
    }
    Ok(Options { elf: elf.ok_or("no ELF given")?, top, json })
}

/// The ELF's function symbols (address with the Thumb bit cleared, demangled name), sorted.
fn symbols(elf: &str) -> Result<Vec<(u32, String)>, String> {
    let out =
        Command::new("arm-none-eabi-nm").args(["-n", "-C", elf]).output().map_err(|e| format!("running arm-none-eabi-nm on {elf}: {e}"))?;
    if !out.status.success() {
        return Err(format!("arm-none-eabi-nm {elf}: {}", String::from_utf8_lossy(&out.stderr).trim()));
    }
    let mut syms: Vec<(u32, String)> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| {
            let mut parts = l.splitn(3, ' ');
            let (addr, kind, name) = (parts.next()?, parts.next()?, parts.next()?);
            matches!(kind, "T" | "t" | "W" | "w").then(|| Some((u32::from_str_radix(addr, 16).ok()? & !1, name.to_string())))?
        })
        .collect();
    syms.sort();
    if syms.is_empty() {
        return Err(format!("{elf} has no function symbols"));
    }
    Ok(syms)
}

/// The hexadecimal number at the start of `s` (up to 8 digits).
fn hex(s: &[u8]) -> Option<u32> {
    let digits = s.iter().take(8).take_while(|c| c.is_ascii_hexdigit()).count();
    u32::from_str_radix(std::str::from_utf8(s.get(..digits)?).ok()?, 16).ok()
}

/// What a log says: instructions per translated block and executions per block, by the block's
/// start address.
struct Blocks {
    sizes: HashMap<u32, u32>,
    execs: HashMap<u32, u64>,
}

/// Reads the blocks' sizes and executions from a log.
fn count(input: impl BufRead) -> Result<Blocks, String> {
    let (mut sizes, mut execs) = (HashMap::new(), HashMap::<u32, u64>::new());
    let mut block: Option<(u32, u32)> = None;
    let mut input = input;
    let mut line = Vec::new();
    loop {
        line.clear();
        if input.read_until(b'\n', &mut line).map_err(|e| format!("reading the log: {e}"))? == 0 {
            break;
        }
        if let Some(rest) = line.strip_prefix(b"Trace ") {
            // `Trace 0: 0x7f… [00000000/000004f0/…] symbol`: the block's guest address is the second field.
            let pc = rest.iter().position(|&c| c == b'[').and_then(|i| rest.get(i + 10..)).and_then(hex);
            if let Some(pc) = pc {
                *execs.entry(pc).or_default() += 1;
            }
        } else if let Some(rest) = line.strip_prefix(b"0x") {
            // An instruction of the block being translated: `0x000004f0:  b580  push {r7, lr}`.
            if let Some(pc) = hex(rest) {
                block = Some(match block {
                    Some((start, n)) => (start, n + 1),
                    None => (pc, 1),
                });
            }
        } else if let Some((start, n)) = block.take() {
            sizes.insert(start, n);
        }
    }
    if let Some((start, n)) = block {
        sizes.insert(start, n);
    }
    if execs.is_empty() {
        return Err("the log has no executed blocks (run QEMU with -d in_asm,exec,nochain)".into());
    }
    Ok(Blocks { sizes, execs })
}

fn run() -> Result<(), String> {
    let o = options()?;
    let syms = symbols(&o.elf)?;
    let Blocks { sizes, execs } = count(BufReader::with_capacity(1 << 20, std::io::stdin().lock()))?;
    let mut per: HashMap<&str, u64> = HashMap::new();
    let (mut total, mut unsized_blocks) = (0u64, 0u64);
    for (pc, n) in &execs {
        let Some(&size) = sizes.get(pc) else {
            unsized_blocks += n;
            continue;
        };
        let i = syms.partition_point(|(a, _)| *a <= *pc);
        let name = i.checked_sub(1).and_then(|i| syms.get(i)).map_or("?", |(_, s)| s.as_str());
        let c = u64::from(size) * n;
        *per.entry(name).or_default() += c;
        total += c;
    }
    let mut rows: Vec<(&str, u64)> = per.into_iter().collect();
    rows.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(b.0)));
    let mut out = std::io::stdout().lock();
    let share = |c: u64| 100.0 * c as f64 / total.max(1) as f64;
    let w = |e: std::io::Error| format!("writing: {e}");
    if o.json {
        let functions: Vec<serde_json::Value> = rows
            .iter()
            .take(o.top)
            .map(|(name, c)| serde_json::json!({ "function": name, "instructions": c, "share": share(*c) / 100.0 }))
            .collect();
        let doc = serde_json::json!({ "format": "gpmm-qemu-profile", "version": 1, "instructions": total, "functions": functions });
        writeln!(out, "{doc}").map_err(w)?;
    } else {
        writeln!(out, "{total} instructions ({} executed blocks never seen translated)", unsized_blocks).map_err(w)?;
        for (name, c) in rows.iter().take(o.top) {
            writeln!(out, "{c:>14} {:5.1} %  {name}", share(*c)).map_err(w)?;
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.is_empty() => {
            eprintln!("usage: gpmm-qemu-profile ELF [--top N] [--json] < QEMU_LOG");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("gpmm-qemu-profile: {e}");
            ExitCode::FAILURE
        }
    }
}
