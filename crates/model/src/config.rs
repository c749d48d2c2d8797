//! The model a run trains: what a training TOML's `[model]` table holds, tagged by `kind`; each
//! detector's own settings live beside it (`person_minkunet::config`, `centerpoint::config`).
//!
//! Every field has the paper's (or, for CenterPoint, CenterPoint's adapted to people) default and
//! every struct is `#[serde(default, deny_unknown_fields)]`, so a TOML section may omit any field
//! and a typo is an error. `kind = "person_minkunet"` or `kind = "centerpoint"` picks the model.

use serde::{Deserialize, Serialize};

use crate::centerpoint::CenterPointConfig;
use crate::person_minkunet::PersonMinkUNetConfig;
use crate::post::PostProcessConfig;

/// Either detector, tagged by `kind`.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ModelConfig {
    /// The sparse Person-MinkUNet (docs/model.md).
    PersonMinkunet(PersonMinkUNetConfig),
    /// The dense CenterPoint-style baseline (docs/model.md).
    Centerpoint(CenterPointConfig),
}

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig::PersonMinkunet(PersonMinkUNetConfig::default())
    }
}

impl ModelConfig {
    /// The config's `kind` tag as written in TOML.
    pub fn kind(&self) -> &'static str {
        match self {
            ModelConfig::PersonMinkunet(_) => "person_minkunet",
            ModelConfig::Centerpoint(_) => "centerpoint",
        }
    }

    /// Checks what serde cannot.
    pub fn validate(&self) -> Result<(), String> {
        match self {
            ModelConfig::PersonMinkunet(c) => c.validate(),
            ModelConfig::Centerpoint(_) => Ok(()),
        }?;
        self.post().validate()
    }

    /// The post-processing of either model.
    pub fn post(&self) -> &PostProcessConfig {
        match self {
            ModelConfig::PersonMinkunet(c) => &c.post,
            ModelConfig::Centerpoint(c) => &c.post,
        }
    }

    /// The post-processing of either model, to change (it does not change what a model learns).
    pub fn post_mut(&mut self) -> &mut PostProcessConfig {
        match self {
            ModelConfig::PersonMinkunet(c) => &mut c.post,
            ModelConfig::Centerpoint(c) => &mut c.post,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::post::NmsKind;

    #[test]
    fn toml_sections_may_omit_fields_and_reject_typos() {
        let c: ModelConfig = toml::from_str("kind = \"person_minkunet\"\nwidth = 0.5\n").unwrap();
        let ModelConfig::PersonMinkunet(p) = &c else { panic!("wrong kind") };
        assert_eq!(p.width, 0.5);
        assert_eq!(p.num_bins, 12);
        assert_eq!(p.cls_weight, 100.0);
        let c: ModelConfig = toml::from_str("kind = \"centerpoint\"\n[post]\nnms = \"circle\"\n").unwrap();
        let ModelConfig::Centerpoint(cp) = &c else { panic!("wrong kind") };
        assert_eq!(cp.layer_nums, vec![3, 5, 5]);
        assert_eq!(cp.post.nms, NmsKind::Circle);
        assert!(toml::from_str::<ModelConfig>("kind = \"centerpoint\"\nwidht = 1.0\n").is_err());
        assert!(toml::from_str::<ModelConfig>("kind = \"pointpillars\"\n").is_err());
        for c in [ModelConfig::default(), ModelConfig::Centerpoint(CenterPointConfig::default())] {
            let text = toml::to_string(&c).unwrap();
            assert_eq!(toml::from_str::<ModelConfig>(&text).unwrap(), c, "{text}");
        }
    }
}
