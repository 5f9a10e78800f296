//! `fusepose objects`: list an object set (built-in or a folder of meshes) or
//! export it as fusepose loads it (metres, textures resolved) as OBJ + MTL +
//! PNG folders with `models_info.json`, which other tools read (the
//! path-traced split's Blender script, `tools/blender/`); or write a
//! procedural object set the same way (for pretraining a trunk).

use std::path::{Path, PathBuf};

use anyhow::Context;
use fusepose_scene::export::export_objects;
use fusepose_scene::mesh_io::checks::{CheckWarning, MissingTextures, SymmetrySuggestion, suggest_symmetry};
use fusepose_scene::mesh_io::load_object_dir_checked;
use fusepose_scene::procedural::procedural_objects;
use fusepose_scene::symmetry_spec::{Describe, SymmetrySpec, apply_symmetry_specs};
use fusepose_scene::{ObjectSet, builtin::builtin_objects};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

/// The object set both subcommands work on.
#[derive(clap::Args)]
struct SetArgs {
    /// Object set: `builtin` or a folder with one subfolder or .obj/.ply file per object.
    #[arg(long, default_value = "builtin")]
    objects: String,
    /// Metres per mesh-file unit (0.001 for millimetre models); not applied to `builtin`
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Declare symmetries as `train --symmetry` does (shown by `list`, written by `export`)
    #[arg(long = "symmetry", value_name = "NAME=KIND")]
    symmetry: Vec<SymmetrySpec>,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Print each object: class id, name, triangles, diameter (mm), symmetry, and the
    /// symmetry its geometry suggests; then any mesh-check warnings.
    List {
        #[command(flatten)]
        set: SetArgs,
    },
    /// Write an object set as fusepose loads it to DIR: DIR/NAME/NAME.{obj,mtl,png}
    /// (metres, the object frame fusepose's poses refer to) and DIR/models_info.json.
    Export {
        /// Output folder (created if missing; existing files are overwritten).
        dir: PathBuf,
        #[command(flatten)]
        set: SetArgs,
    },
    /// Write a procedural object set to DIR as `export` does: COUNT varied textured
    /// objects (a body solid with up to two parts attached off-centre), for pretraining
    /// a trunk that other object sets warm-start from (`train --warm-start`).
    Procedural {
        /// Output folder (created if missing; existing files are overwritten).
        dir: PathBuf,
        /// How many objects.
        #[arg(long, default_value_t = 40)]
        count: usize,
        /// The same seed and count always write the same objects.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Put the eight built-in objects first (class ids 1..8), then the procedural ones.
        #[arg(long)]
        with_builtin: bool,
    },
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::List { set } => print_listing(&set.objects, set.scale, &set.symmetry),
        Command::Export { dir, set: args } => {
            let mut set = load_set(&args.objects, args.scale)?.0;
            apply_symmetry_specs(&mut set, &args.symmetry)?;
            let info = export_objects(&set, &dir).with_context(|| format!("exporting to {}", dir.display()))?;
            println!("wrote {} objects and {}", set.len(), info.display());
            Ok(())
        }
        Command::Procedural { dir, count, seed, with_builtin } => {
            let mut set = if with_builtin { builtin_objects() } else { ObjectSet::default() };
            set.objects.extend(procedural_objects(count, seed).objects);
            let info = export_objects(&set, &dir).with_context(|| format!("exporting to {}", dir.display()))?;
            println!("wrote {} objects and {}", set.len(), info.display());
            Ok(())
        }
    }
}

/// `builtin`, or the mesh folder `objects` with its mesh-check warnings.
fn load_set(objects: &str, scale: f64) -> anyhow::Result<(ObjectSet, Vec<CheckWarning>)> {
    if objects == "builtin" {
        return Ok((builtin_objects(), Vec::new()));
    }
    load_object_dir_checked(Path::new(objects), scale, MissingTextures::Warn)
        .with_context(|| format!("loading object set '{objects}'"))
}

/// Prints the listing of `objects` (see `List`) with the `--symmetry`
/// declarations applied, and any mesh-check warnings; `train --stage all`
/// prints it before training, so a wrong unit or a symmetry to declare shows
/// before the hour is spent.
pub fn print_listing(objects: &str, scale: f64, symmetry: &[SymmetrySpec]) -> anyhow::Result<()> {
    let (mut set, warnings) = load_set(objects, scale)?;
    apply_symmetry_specs(&mut set, symmetry)?;
    let suggested: Vec<SymmetrySuggestion> = set.objects.iter().map(suggest_symmetry).collect();
    print!("{}", table(&set, &suggested));
    let undeclared = set.objects.iter().zip(&suggested);
    let undeclared = undeclared.filter(|(o, s)| !o.symmetry.is_symmetric() && **s != SymmetrySuggestion::None);
    let undeclared: Vec<&str> = undeclared.map(|(o, _)| o.name.as_str()).collect();
    if !undeclared.is_empty() {
        println!(
            "note: the geometry of {} suggests a symmetry that is not declared (training, ADD(S) and the weight file use the declared one): \
             declare it with --symmetry NAME=KIND (none, continuous:x|y|z, N-fold:x|y|z, box, suggested) or --symmetry suggested, \
             unless a texture breaks it",
            undeclared.join(", ")
        );
    }
    for w in &warnings {
        println!("warning: {w}");
    }
    Ok(())
}

/// The listing: one line per object, class id first; the last column is a
/// suggestion computed from the shape only (a texture may break it), never applied.
fn table(set: &ObjectSet, suggested: &[SymmetrySuggestion]) -> String {
    let width = set.objects.iter().map(|o| o.name.len()).max().unwrap_or(4).max(4);
    let declared: Vec<String> = set.objects.iter().map(|o| Describe(&o.symmetry).to_string()).collect();
    let sym_width = declared.iter().map(|d| d.len()).max().unwrap_or(8).max(8);
    let mut out = format!(
        "{:>5}  {:<width$}  {:>9}  {:>13}  {:<sym_width$}  suggested from geometry\n",
        "class", "name", "triangles", "diameter (mm)", "symmetry"
    );
    for (i, ((o, declared), suggested)) in set.objects.iter().zip(&declared).zip(suggested).enumerate() {
        out += &format!(
            "{:>5}  {:<width$}  {:>9}  {:>13.1}  {:<sym_width$}  {}\n",
            i + 1,
            o.name,
            o.mesh.triangles.len(),
            o.diameter * 1e3,
            declared,
            suggested
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_listing_names_every_object_with_its_diameter() {
        let set = builtin_objects();
        let suggested: Vec<_> = set.objects.iter().map(suggest_symmetry).collect();
        let text = table(&set, &suggested);
        assert_eq!(text.lines().count(), set.len() + 1);
        let cracker = text.lines().find(|l| l.contains("cracker_box")).unwrap();
        assert!(
            cracker.trim_start().starts_with("1 ") && cracker.contains("270.7") && cracker.contains(" none "),
            "{cracker}"
        );
        assert!(text.lines().next().unwrap().ends_with("suggested from geometry"));
        assert!(text.lines().any(|l| l.contains("wood_block") && l.contains("discrete (7 + identity)")));
        // Declared continuous, and suggested continuous about (≈ 0, ≈ 0, 1).
        let bowl = text.lines().find(|l| l.contains("bowl")).unwrap();
        assert!(bowl.contains("through") && bowl.contains("continuous about (") && bowl.ends_with(", 1.00)"), "{bowl}");
        let mug = text.lines().find(|l| l.contains("mug")).unwrap();
        assert!(mug.ends_with(" none"), "{mug}");
    }
}
