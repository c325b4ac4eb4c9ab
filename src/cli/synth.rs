//! `polishbot synth`: writes reference.ply, scan.ply and truth.json.
use clap::Args;

/// Arguments of `synth`.
#[derive(Debug, Args)]
pub struct SynthArgs {}

/// Writes the synthetic case.
pub fn run(_args: SynthArgs, _config: Option<&std::path::Path>) -> anyhow::Result<()> {
    anyhow::bail!("synth: not implemented yet")
}
