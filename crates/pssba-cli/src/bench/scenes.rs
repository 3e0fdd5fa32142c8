//! Which scenes a bench runs: the four built-ins always, `mbs` and `crane` from the CARIC
//! meshes when their folder is found.

use anyhow::{Context, bail};
use pssba_sim::{BuiltinScene, Scene, TriangleMesh};
use std::path::{Path, PathBuf};

/// The CARIC scenes: bench name and STL file.
const CARIC: [(&str, &str); 2] = [("mbs", "mbs.stl"), ("crane", "construction_crane_1.stl")];

/// Column order: the paper's Table I scenes first (MBS, Hangar, Crane, Street), then ours.
const TABLE_ORDER: [&str; 6] = ["mbs", "hangar", "crane", "street", "curved", "truss"];

/// A scene to benchmark, not yet built (meshes load when their turn comes).
#[derive(Debug, Clone)]
pub enum SceneSource {
    /// A procedural scene.
    Builtin(BuiltinScene),
    /// A CARIC STL mesh: bench name and path.
    Mesh(&'static str, PathBuf),
}

impl SceneSource {
    /// The name in tables and JSON.
    pub fn name(&self) -> &str {
        match self {
            SceneSource::Builtin(scene) => scene.name(),
            SceneSource::Mesh(name, _) => name,
        }
    }

    /// Builds the mesh and its default trajectory (STL scenes get a ground plane, as in
    /// `pssba simulate`).
    pub fn build(&self) -> anyhow::Result<Scene> {
        match self {
            SceneSource::Builtin(scene) => Ok(scene.build()),
            SceneSource::Mesh(name, path) => {
                let triangles = pssba_io::read_stl(path)?;
                Scene::from_mesh(name, TriangleMesh::from_triangles(&triangles), true)
                    .with_context(|| format!("{}: cannot ray-cast this mesh", path.display()))
            }
        }
    }
}

/// Every valid scene name.
pub fn valid_names() -> Vec<&'static str> {
    let builtin = BuiltinScene::ALL.iter().map(|s| s.name());
    builtin.chain(CARIC.iter().map(|(name, _)| *name)).collect()
}

/// Where `../shared/data/caric` may be: relative to the current directory, to any ancestor
/// of the executable (its target dir sits in or beside the workspace), and to the source
/// workspace this binary was built from.
fn caric_candidates() -> Vec<PathBuf> {
    let relative = Path::new("../shared/data/caric");
    let mut candidates = vec![relative.to_path_buf()];
    if let Ok(exe) = std::env::current_exe() {
        for dir in exe.ancestors().skip(1) {
            candidates.push(dir.join(relative));
            candidates.push(dir.join("shared/data/caric"));
        }
    }
    candidates.push(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../..")
            .join(relative),
    );
    candidates
}

/// The CARIC folder: `--caric` (which must exist), else the first candidate holding mbs.stl.
fn find_caric(explicit: Option<&Path>) -> anyhow::Result<Option<PathBuf>> {
    if let Some(dir) = explicit {
        if !dir.is_dir() {
            bail!("--caric {}: not a directory", dir.display());
        }
        return Ok(Some(dir.to_path_buf()));
    }
    Ok(caric_candidates()
        .into_iter()
        .find(|dir| dir.join(CARIC[0].1).is_file()))
}

/// The scenes to run, in order. Unknown names are an error listing the valid ones; naming a
/// CARIC scene whose folder is missing is an error; by default missing CARIC scenes are
/// skipped with a message on stderr.
pub fn resolve(names: Option<&[String]>, caric: Option<&Path>) -> anyhow::Result<Vec<SceneSource>> {
    let valid = valid_names();
    if let Some(unknown) = names
        .unwrap_or_default()
        .iter()
        .find(|n| !valid.contains(&n.as_str()))
    {
        bail!(
            "--scenes: unknown scene '{unknown}'; valid scenes: {}",
            valid.join(", ")
        );
    }
    let caric_dir = find_caric(caric)?;
    let wanted = |name: &str| names.is_none_or(|list| list.iter().any(|n| n == name));
    let mut scenes: Vec<SceneSource> = BuiltinScene::ALL
        .into_iter()
        .filter(|s| wanted(s.name()))
        .map(SceneSource::Builtin)
        .collect();
    let caric_wanted: Vec<_> = CARIC.iter().filter(|(name, _)| wanted(name)).collect();
    match caric_dir {
        Some(dir) => {
            for (name, file) in caric_wanted {
                let path = dir.join(file);
                if !path.is_file() {
                    bail!("scene {name}: {} not found", path.display());
                }
                scenes.push(SceneSource::Mesh(name, path));
            }
        }
        None if names.is_some() && !caric_wanted.is_empty() => {
            let listed: Vec<&str> = caric_wanted.iter().map(|(n, _)| *n).collect();
            bail!(
                "scenes {}: ../shared/data/caric not found (pass --caric DIR)",
                listed.join(", ")
            );
        }
        None => {
            let listed: Vec<&str> = caric_wanted.iter().map(|(n, _)| *n).collect();
            eprintln!(
                "skipping {}: ../shared/data/caric not found",
                listed.join(", ")
            );
        }
    }
    scenes.sort_by_key(|s| TABLE_ORDER.iter().position(|n| *n == s.name()));
    if scenes.is_empty() {
        bail!(
            "--scenes: no scene selected; valid scenes: {}",
            valid.join(", ")
        );
    }
    Ok(scenes)
}
