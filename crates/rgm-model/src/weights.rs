//! Trained weights that ship with rgm: `weights/manifest.json` lists each model (what it was
//! trained on, its sizes, its file); the one marked `builtin` is embedded in the binary, so
//! `rgm register` works without a weight file.
//!
//! ```json
//! {"models": [{"name": "partial-fast", "setting": "partial", "unseen": false,
//!   "variant": "rgm", "preset": "fast", "match_points": 384,
//!   "file": "partial-fast.safetensors", "builtin": true,
//!   "trained_with": "rgm train --setting partial --preset fast --out runs/partial-fast",
//!   "epochs": 0.5, "pairs_seen": 4000, "note": "..."}]}
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use rgm_data::Setting;

use crate::error::MethodError;
use crate::network::{Config, Edges, Rgm, Scoring, TestStatistics};
use crate::procedure::{ProcedureConfig, RgmRegistrar};

/// The manifest embedded at build time.
const BUILTIN_MANIFEST: &str = include_str!("../weights/manifest.json");

/// The weight file embedded at build time: the manifest's `builtin` entry names this file (a
/// test checks it).
const BUILTIN_FILE: &str = "partial-fast.safetensors";
static BUILTIN_WEIGHTS: &[u8] = include_bytes!("../weights/partial-fast.safetensors");

/// The folder of the shipped weight files in the source tree.
pub fn weights_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("weights")
}

/// The network's structure: the full model or one of the ablations of spec §2.7.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Variant {
    /// AIS scoring and transformer edges.
    #[default]
    Rgm,
    /// Var1: distance scoring instead of AIS.
    Var1,
    /// Var2: full connection instead of transformer edges.
    Var2,
}

impl Variant {
    pub const ALL: [Variant; 3] = [Variant::Rgm, Variant::Var1, Variant::Var2];

    /// Lower-case name, as the manifest and the command line spell it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Rgm => "rgm",
            Self::Var1 => "var1",
            Self::Var2 => "var2",
        }
    }

    /// `config` with this variant's scoring and edges (spec §2.7).
    pub fn apply(self, mut config: Config) -> Config {
        match self {
            Variant::Rgm => {}
            Variant::Var1 => config.scoring = Scoring::Var1,
            Variant::Var2 => config.edges = Edges::Full,
        }
        config
    }
}

impl std::str::FromStr for Variant {
    type Err = MethodError;

    fn from_str(s: &str) -> Result<Self, MethodError> {
        Self::ALL
            .into_iter()
            .find(|v| v.name() == s)
            .ok_or_else(|| {
                MethodError::InvalidOptions(format!(
                    "unknown variant `{s}` (expected rgm, var1 or var2)"
                ))
            })
    }
}

/// Where a model's safetensors file is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WeightsFile {
    /// A file relative to the manifest's folder (`partial-fast.safetensors`).
    Path(PathBuf),
    /// A file that a commit of the project's history holds (`git:REV:PATH` in the manifest:
    /// an earlier built-in model, or a run's weights its folder has since replaced), kept out
    /// of the tree so that git does not store the same bytes twice; `git show REV:PATH` writes
    /// it out.
    Git { revision: String, path: String },
}

impl WeightsFile {
    /// The file on disk, for a manifest in `dir`; an error for a file of the history, which
    /// must be written out first.
    pub fn on_disk(&self, dir: &Path) -> Result<PathBuf, MethodError> {
        match self {
            Self::Path(path) => Ok(dir.join(path)),
            Self::Git { .. } => Err(MethodError::Manifest {
                path: dir.join("manifest.json"),
                why: format!("{self} is in the git history, not on disk (`git show` writes it)"),
            }),
        }
    }
}

impl std::fmt::Display for WeightsFile {
    /// As the manifest spells it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Path(path) => write!(f, "{}", path.display()),
            Self::Git { revision, path } => write!(f, "git:{revision}:{path}"),
        }
    }
}

impl std::str::FromStr for WeightsFile {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let Some(object) = s.strip_prefix("git:") else {
            return Ok(Self::Path(PathBuf::from(s)));
        };
        match object.split_once(':') {
            Some((revision, path)) if !revision.is_empty() && !path.is_empty() => Ok(Self::Git {
                revision: revision.to_string(),
                path: path.to_string(),
            }),
            _ => Err(format!("{s:?} is not git:REV:PATH")),
        }
    }
}

impl Serialize for WeightsFile {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for WeightsFile {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        String::deserialize(deserializer)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

/// One trained model of the manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelEntry {
    /// Short name (`partial-fast`).
    pub name: String,
    /// The test protocol it was trained for.
    #[serde(with = "crate::by_name")]
    pub setting: Setting,
    /// Trained on categories 0–19 only (the unseen-categories protocol).
    pub unseen: bool,
    /// Full model or ablation.
    #[serde(with = "crate::by_name")]
    pub variant: Variant,
    /// The network sizes ([`Config::preset`]).
    pub preset: String,
    /// Clouds are randomly subsampled to this many points for matching (usually as in
    /// training); `None` matches on the full clouds (chosen on validation pairs for some models
    /// trained on subsets: `docs/training/match-points/`).
    pub match_points: Option<usize>,
    /// The safetensors file.
    pub file: WeightsFile,
    /// Whether this is the model embedded in the binary (exactly one is).
    pub builtin: bool,
    /// The command that trained it.
    pub trained_with: String,
    /// Epochs of training (fractional when cut short).
    pub epochs: f64,
    /// Training pairs seen.
    pub pairs_seen: u64,
    /// Batch-norm statistics at test time: `cloud` for models trained by `rgm train` (each
    /// cloud normalised on its own, as in its training), `running` (the default) for
    /// PyTorch-trained ones.
    #[serde(default)]
    pub test_statistics: TestStatistics,
    /// Anything else worth knowing.
    #[serde(default)]
    pub note: String,
}

/// The list of trained models.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub models: Vec<ModelEntry>,
}

impl Manifest {
    /// Reads a manifest file.
    pub fn load(path: &Path) -> Result<Self, MethodError> {
        let text = std::fs::read_to_string(path).map_err(|e| MethodError::Manifest {
            path: path.to_path_buf(),
            why: e.to_string(),
        })?;
        Self::parse(&text, path)
    }

    /// The manifest embedded in the binary.
    pub fn builtin() -> Self {
        Self::parse(BUILTIN_MANIFEST, &weights_dir().join("manifest.json"))
            .expect("the embedded manifest parses (tested)")
    }

    fn parse(text: &str, path: &Path) -> Result<Self, MethodError> {
        serde_json::from_str(text).map_err(|e| MethodError::Manifest {
            path: path.to_path_buf(),
            why: e.to_string(),
        })
    }

    /// The model called `name`.
    pub fn get(&self, name: &str) -> Option<&ModelEntry> {
        self.models.iter().find(|m| m.name == name)
    }

    /// The entry marked `builtin`.
    pub fn builtin_entry(&self) -> Option<&ModelEntry> {
        self.models.iter().find(|m| m.builtin)
    }
}

/// The bytes of the built-in model's safetensors file.
pub fn builtin_weights() -> &'static [u8] {
    BUILTIN_WEIGHTS
}

impl ModelEntry {
    /// The network configuration: the preset's sizes with the variant's scoring and edges.
    pub fn config(&self) -> Result<Config, MethodError> {
        Ok(self.variant.apply(Config::preset(&self.preset)?))
    }

    /// The paper's test-time settings, matching on as many points as in training.
    pub fn procedure_config(&self) -> ProcedureConfig {
        ProcedureConfig {
            match_points: self.match_points,
            ..ProcedureConfig::default()
        }
    }

    /// RGM with this model's weights, read from `dir` (the manifest's folder).
    pub fn registrar(&self, dir: &Path) -> Result<RgmRegistrar, MethodError> {
        let network = Rgm::load(self.config()?, &self.file.on_disk(dir)?)?;
        Ok(self.registrar_of(network))
    }

    fn registrar_of(&self, mut network: Rgm<f32>) -> RgmRegistrar {
        network.featurer.test_statistics = self.test_statistics;
        RgmRegistrar::new(network, self.procedure_config())
    }
}

/// RGM of `config`'s sizes with the weights in the safetensors file `weights` (the authors'
/// parameter names), and the paper's test-time settings.
pub fn load_registrar(config: Config, weights: &Path) -> Result<RgmRegistrar, MethodError> {
    let network = Rgm::load(config, weights)?;
    Ok(RgmRegistrar::new(network, ProcedureConfig::default()))
}

/// RGM with the built-in model (weights embedded in the binary) and its test-time settings.
pub fn builtin_registrar() -> Result<RgmRegistrar, MethodError> {
    let manifest = Manifest::builtin();
    let entry = manifest
        .builtin_entry()
        .ok_or_else(|| MethodError::Manifest {
            path: weights_dir().join("manifest.json"),
            why: "no model is marked builtin".to_string(),
        })?;
    let origin = Path::new("builtin:").join(BUILTIN_FILE);
    let network = Rgm::from_bytes(entry.config()?, builtin_weights(), &origin)?;
    Ok(entry.registrar_of(network))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_manifest_names_the_embedded_file_once() {
        let manifest = Manifest::builtin();
        let builtin: Vec<_> = manifest.models.iter().filter(|m| m.builtin).collect();
        assert_eq!(builtin.len(), 1, "{manifest:?}");
        assert_eq!(builtin[0].file, WeightsFile::Path(BUILTIN_FILE.into()));
        // The file on disk is the one embedded.
        let on_disk = std::fs::read(weights_dir().join(BUILTIN_FILE)).unwrap();
        assert!(on_disk == builtin_weights());
    }

    #[test]
    fn variants_select_the_ablations_and_match_points_carry_over() {
        let mut entry = Manifest::builtin().builtin_entry().unwrap().clone();
        entry.preset = "tiny".into();
        entry.match_points = Some(100);
        let base = entry.config().unwrap();
        assert_eq!(base, Config::tiny());
        entry.variant = Variant::Var1;
        assert_eq!(entry.config().unwrap().scoring, Scoring::Var1);
        entry.variant = Variant::Var2;
        assert_eq!(entry.config().unwrap().edges, Edges::Full);
        assert_eq!(entry.procedure_config().match_points, Some(100));
        assert_eq!(entry.procedure_config().passes, 2);
    }

    #[test]
    fn an_entry_loads_its_file_and_the_builtin_model_its_embedded_bytes() {
        let mut entry = Manifest::builtin().builtin_entry().unwrap().clone();
        let file = "rgm_tiny_state_dict.safetensors";
        (entry.preset, entry.file) = ("tiny".into(), WeightsFile::Path(file.into()));
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
        let registrar = entry.registrar(&dir).unwrap();
        let on_disk = Rgm::<f32>::load(Config::tiny(), &dir.join(file)).unwrap();
        assert_eq!(
            registrar.network.blocks[1].u_fc.weight.value,
            on_disk.blocks[1].u_fc.weight.value
        );
        assert_eq!(registrar.config.match_points, entry.match_points);
        // The built-in model: the embedded bytes, the manifest's sizes and matching size.
        let builtin = Manifest::builtin().builtin_entry().unwrap().clone();
        let registrar = builtin_registrar().unwrap();
        let expected = builtin.registrar(&weights_dir()).unwrap();
        assert_eq!(registrar.network.config(), &builtin.config().unwrap());
        assert_eq!(registrar.config, expected.config);
        assert_eq!(
            registrar.network.featurer.convs[0].weight.value,
            expected.network.featurer.convs[0].weight.value
        );
    }

    #[test]
    fn a_bad_manifest_names_the_file_and_the_fault() {
        let dir = std::env::temp_dir().join(format!("rgm-manifest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("manifest.json");
        let err = Manifest::load(&path).unwrap_err().to_string();
        assert!(
            err.starts_with(&format!("weights manifest {}: ", path.display())),
            "{err}"
        );
        std::fs::write(&path, r#"{"models": [{"name": "x", "variant": "var3"}]}"#).unwrap();
        let err = Manifest::load(&path).unwrap_err().to_string();
        assert!(err.contains("unknown variant `var3`"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_weights_file_of_the_history_is_parsed_and_spelled_back_and_not_read_from_disk() {
        let text = "git:ec2894e:crates/rgm-model/weights/partial-fast.safetensors";
        let file: WeightsFile = text.parse().unwrap();
        assert_eq!(
            file,
            WeightsFile::Git {
                revision: "ec2894e".into(),
                path: "crates/rgm-model/weights/partial-fast.safetensors".into()
            }
        );
        assert_eq!(file.to_string(), text);
        assert_eq!(serde_json::to_value(&file).unwrap(), text);
        let err = file.on_disk(Path::new("w")).unwrap_err().to_string();
        assert!(
            err.contains(&format!("{text} is in the git history")),
            "{err}"
        );
        let plain: WeightsFile = "a.safetensors".parse().unwrap();
        assert_eq!(
            plain.on_disk(Path::new("w")).unwrap(),
            Path::new("w/a.safetensors")
        );
        assert!("git:abc".parse::<WeightsFile>().is_err());
        // Every file of the shipped manifest is spelled back as the manifest spells it.
        let text = std::fs::read_to_string(weights_dir().join("manifest.json")).unwrap();
        let read: serde_json::Value = serde_json::from_str(&text).unwrap();
        let files: Vec<String> = Manifest::builtin()
            .models
            .iter()
            .map(|m| m.file.to_string())
            .collect();
        let spelled: Vec<&str> = read["models"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m["file"].as_str().unwrap())
            .collect();
        assert_eq!(files, spelled);
        assert!(files.iter().any(|f| f.starts_with("git:")), "{files:?}");
    }
}
