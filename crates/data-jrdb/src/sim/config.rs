//! The `[data.simulate]` settings: which simulated tree to generate when `data.root` is missing.

use serde::{Deserialize, Serialize};

use super::{Naming, Preset, SynthConfig};

/// The simulated dataset generated when `data.root` is missing (deterministic by `seed`).
///
/// `preset = "bench-v1"` names the simulated benchmark (`Preset`); keys written
/// beside it override the preset's values, keys left out take the preset's (or, without a
/// preset, the simulator's own defaults, [`SynthConfig::default`]).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimulateConfig {
    /// A named benchmark the other keys start from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preset: Option<Preset>,
    /// Sequences (without a preset: [`SynthConfig`]'s default); each is its own scene.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sequences: Option<usize>,
    /// Frames per sequence (without a preset: [`SynthConfig`]'s default).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames: Option<usize>,
    /// Seed of the scenes and scans.
    pub seed: u64,
    /// Most people per scene (40 without a preset).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_people: Option<usize>,
    /// People farther than this (BEV metres) are not labelled (35 without a preset).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub label_range: Option<f64>,
    /// Simulation steps of 1/15 s between written frames (1 without a preset).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frame_step: Option<usize>,
    /// Sequence names: `jrdb` (JRDB's, its default split) or `benchmark` (`sim-val-*` for validation).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub naming: Option<Naming>,
    /// A folder of real scans with their people removed (`backdrops.csv`, see
    /// `sim::backdrop`): simulated people are ray-cast into them instead of into simulated
    /// places. Training sequences only (`bd-train-*`); `preset` is not used with it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backdrops: Option<std::path::PathBuf>,
    /// With `backdrops`: the share of its sequences (0–1) whose real scan is thinned to a
    /// 32-beam sensor's density (rings 1.2° apart, columns 0.33°), people ray-cast with the kept
    /// beams: far, sparse people in a place sampled as sparsely (0 without it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub thinned_share: Option<f64>,
}

impl SimulateConfig {
    /// The simulator's own config: the preset's (or the plain defaults), then the keys set here.
    pub fn synth(&self) -> SynthConfig {
        let base = match self.preset {
            Some(p) => p.synth(self.seed),
            None => SynthConfig { seed: self.seed, ..Default::default() },
        };
        SynthConfig {
            sequences: self.sequences.unwrap_or(base.sequences),
            frames: self.frames.unwrap_or(base.frames),
            max_people: self.max_people.unwrap_or(base.max_people),
            label_range: self.label_range.unwrap_or(base.label_range),
            frame_step: self.frame_step.unwrap_or(base.frame_step),
            naming: self.naming.unwrap_or(base.naming),
            world: if self.backdrops.is_some() { super::World::Backdrops } else { base.world },
            backdrops: self.backdrops.clone(),
            thinned_share: self.thinned_share.unwrap_or(base.thinned_share),
            ..base
        }
    }
}
