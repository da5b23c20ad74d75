//! Decodes the firmware's defmt stream against its ELF.
//!
//! `gpmm-defmt-decode ELF [--figures [KEY=VALUE ...]] < RAW`
//!
//! RAW is what the firmware wrote to the semihosting stdout (raw rzcobs-encoded defmt
//! frames, as `defmt-semihosting` writes them). Every frame is printed as one line,
//! `LEVEL message`. With `--figures`, a last line `GPMM_FIGURES {json}` follows: every
//! `key=value` token found in the decoded messages (the last value of a key wins;
//! integers stay numbers, anything else becomes a string) plus the KEY=VALUE pairs
//! given on the command line (run.sh adds the linker's size figures that way).
//!
//! Exit status: 0 if the whole stream decoded, 2 on a bad ELF or a malformed stream.

use std::collections::BTreeMap;
use std::io::Read;
use std::process::ExitCode;

use defmt_decoder::{DecodeError, Table};

fn main() -> ExitCode {
    match run() {
        Ok(code) => code,
        Err(e) => {
            eprintln!("gpmm-defmt-decode: {e}");
            ExitCode::from(2)
        }
    }
}

fn run() -> Result<ExitCode, String> {
    let mut args = std::env::args().skip(1);
    let elf_path = args.next().ok_or("usage: gpmm-defmt-decode ELF [--figures [KEY=VALUE ...]] < RAW")?;
    let mut figures_wanted = false;
    let mut extra = Vec::new();
    for a in args {
        if a == "--figures" {
            figures_wanted = true;
        } else if figures_wanted {
            extra.push(a);
        } else {
            return Err(format!("unexpected argument {a:?}"));
        }
    }

    let elf = std::fs::read(&elf_path).map_err(|e| format!("reading {elf_path}: {e}"))?;
    let table = Table::parse(&elf)
        .map_err(|e| format!("parsing {elf_path}: {e}"))?
        .ok_or_else(|| format!("{elf_path} has no .defmt section"))?;

    let mut raw = Vec::new();
    std::io::stdin().read_to_end(&mut raw).map_err(|e| format!("reading stdin: {e}"))?;

    let mut figures: BTreeMap<String, String> = BTreeMap::new();
    let mut decoder = table.new_stream_decoder();
    decoder.received(&raw);
    let mut frames = 0usize;
    let mut status = ExitCode::SUCCESS;
    loop {
        match decoder.decode() {
            Ok(frame) => {
                frames += 1;
                let level = frame.level().map(|l| l.as_str().to_ascii_uppercase()).unwrap_or_else(|| "PRINT".into());
                let message = frame.display_message().to_string();
                println!("{level:<5} {message}");
                for tok in message.split_whitespace() {
                    if let Some((k, v)) = tok.split_once('=') {
                        if is_key(k) && !v.is_empty() {
                            figures.insert(k.to_string(), v.trim_end_matches([',', ';']).to_string());
                        }
                    }
                }
            }
            Err(DecodeError::UnexpectedEof) => break,
            Err(DecodeError::Malformed) => {
                eprintln!("gpmm-defmt-decode: malformed frame after {frames} good ones");
                status = ExitCode::from(2);
                if !table.encoding().can_recover() {
                    break;
                }
            }
        }
    }
    if frames == 0 {
        eprintln!("gpmm-defmt-decode: no defmt frame in {} bytes of input", raw.len());
    }

    if figures_wanted {
        for kv in extra {
            let (k, v) = kv.split_once('=').ok_or_else(|| format!("not KEY=VALUE: {kv:?}"))?;
            figures.insert(k.to_string(), v.to_string());
        }
        let body: Vec<String> = figures.iter().map(|(k, v)| format!("\"{}\":{}", k, json_value(v))).collect();
        println!("GPMM_FIGURES {{{}}}", body.join(","));
    }
    Ok(status)
}

fn is_key(k: &str) -> bool {
    let mut chars = k.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_lowercase() || c == '_')
        && chars.all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

fn json_value(v: &str) -> String {
    if v.parse::<i64>().is_ok() || v.parse::<u64>().is_ok() {
        return v.to_string();
    }
    let mut s = String::with_capacity(v.len() + 2);
    s.push('"');
    for c in v.chars() {
        match c {
            '"' => s.push_str("\\\""),
            '\\' => s.push_str("\\\\"),
            c if (c as u32) < 0x20 => s.push_str(&format!("\\u{:04x}", c as u32)),
            c => s.push(c),
        }
    }
    s.push('"');
    s
}
