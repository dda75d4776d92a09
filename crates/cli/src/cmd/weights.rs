//! `pgrf import-weights` and `pgrf export-weights`: the field's published
//! PyTorch SID U-Nets in, pgrf's networks out (`pgrf_nn::interop`).

use anyhow::{bail, Context, Result};
use clap::Args;
use pgrf_nn::interop::{self, Source};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// PyTorch checkpoint (.pth/.pt; the state dict at the top or nested under a key such as state_dict, model, netG; `module.` prefixes stripped) or safetensors file.
    pub file: PathBuf,
    /// The architecture the file holds: sid-unet (UNetSeeInDark of SID, ELD, PMN, PNNP, LED).
    #[arg(long, default_value = "sid-unet")]
    pub arch: String,
    /// The repository the weights come from (sid, eld, pmn, pnnp, led): its input convention is recorded in the file and printed.
    #[arg(long)]
    pub from: Option<Source>,
    /// The nesting to import when the file holds the network more than once (LED: params, params_ema, params_deploy); default the shortest.
    #[arg(long)]
    pub key: Option<String>,
    /// pgrf weight file to write (safetensors, written atomically).
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn run_import(a: &ImportArgs) -> Result<()> {
    if a.arch != "sid-unet" {
        bail!(
            "--arch {}: pgrf imports the SID U-Net (sid-unet) only; the published low-light models of SID, ELD, PMN, PNNP and LED are all that network",
            a.arch
        );
    }
    let imported = interop::import_sid(&a.file, a.from, a.key.as_deref())?;
    let bytes = imported.encode()?;
    pgrf_core::write_atomic(&a.output, &bytes)
        .with_context(|| format!("-o {}", a.output.display()))?;
    let from = imported.meta.imported.as_ref().expect("set by import");
    let params: usize = imported.tensors.values().map(|t| t.values.len()).sum();
    eprintln!(
        "wrote {}: {} from {} ({}, {} tensors{}), {params} parameters",
        a.output.display(),
        imported.meta.arch.describe(),
        a.file.display(),
        from.container,
        imported.tensors.len(),
        if from.nesting.is_empty() {
            String::new()
        } else {
            format!(" under '{}'", from.nesting)
        },
    );
    if !from.also_under.is_empty() {
        eprintln!(
            "note: the file also holds the network under {}; --key picks another",
            from.also_under.join(", ")
        );
    }
    match &from.convention {
        Some(c) => eprintln!("convention ({}): {c}", from.repository.as_deref().unwrap_or("")),
        None => eprintln!(
            "no --from: the file records no input convention (docs/guide.md, \"Published models\", lists each repository's)"
        ),
    }
    Ok(())
}

#[derive(Args, Debug)]
pub struct ExportArgs {
    /// pgrf weight file (from `pgrf train` or `pgrf import-weights`).
    pub model: PathBuf,
    /// Target framework: torch.
    #[arg(long, default_value = "torch")]
    pub to: String,
    /// Output: .pth (torch.save's zip format) or .safetensors (written atomically).
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn run_export(a: &ExportArgs) -> Result<()> {
    if a.to != "torch" {
        bail!("--to {}: pgrf exports to torch only", a.to);
    }
    let ext = a
        .output
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    let pth = match ext.as_deref() {
        Some("pth") | Some("pt") => true,
        Some("safetensors") => false,
        _ => bail!(
            "-o {}: name the output .pth, .pt or .safetensors",
            a.output.display()
        ),
    };
    let (meta, tensors, out) = interop::export_file(&a.model, pth)?;
    pgrf_core::write_atomic(&a.output, &out.bytes)
        .with_context(|| format!("-o {}", a.output.display()))?;
    eprintln!(
        "wrote {}: {} in {}, {} tensors",
        a.output.display(),
        meta.arch.describe(),
        out.naming,
        tensors
    );
    if out.residual {
        eprintln!(
            "{}",
            match meta.arch {
                pgrf_nn::Architecture::SidUnet(_) =>
                    "note: this network is residual: add the input to UNetSeeInDark's output (tests/reference/sid_unet_torch.py check --residual)",
                pgrf_nn::Architecture::Sr3(_) =>
                    "note: this network is residual: v = (T + network - Xt) / max(1 - t, 0.1) (bench/sr3_reference.py, --config the pgrf file for its settings)",
                pgrf_nn::Architecture::Sr3Prior(_) =>
                    "note: this network is residual around its prior's restoration P (the prior.* tensors, an SPC SID U-Net, read as the condition's last four planes): v = (P + network - Xt) / max(1 - t, 0.1); bench/sr3_reference.py builds the field, not the prior",
            }
        );
    }
    Ok(())
}
