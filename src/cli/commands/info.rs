//! `vcsmooth info IN [--json]`: a mesh's vertices, faces, edges, boundary, components, volume,
//! area and bounding box, and what its file carries besides positions and faces (kept by an
//! output in the same format), as a table or JSON.

use std::io::Write;
use std::path::PathBuf;

use clap::Args as ClapArgs;

use crate::cli::output::print_json;
use crate::cli::progress::Progress;
use crate::cli::report::{UNDEFINED, count, fixed, num, print_rows};
use crate::error::Result;
use crate::mesh::Carried;
use crate::metrics::MeshInfo;
use crate::report::{InfoDoc, format_name, undefined_as_nan};

/// `vcsmooth info IN [--json]`
#[derive(Debug, Clone, ClapArgs)]
pub struct InfoArgs {
    /// Mesh to describe (PLY, OBJ, OFF, STL, glTF or GLB; any of them gzip-compressed).
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// Print JSON instead of a table [default: table].
    #[arg(long)]
    pub json: bool,
    /// Count vertices that share a position apart, as `smooth --no-weld` smooths them [default: copies of a position are one vertex, as smooth welds them].
    #[arg(long)]
    pub no_weld: bool,
    /// Also count vertices closer than D as one, as `smooth --weld-tolerance D` welds them.
    #[arg(long, value_name = "D", value_parser = crate::cli::shared::length, allow_hyphen_values = true, conflicts_with = "no_weld")]
    pub weld_tolerance: Option<f64>,
}

/// `vcsmooth info`, resolved.
#[derive(Debug, Clone)]
pub struct InfoConfig {
    pub input: PathBuf,
    pub json: bool,
    pub weld: crate::partition::Weld,
}

impl InfoConfig {
    pub fn from_args(a: InfoArgs) -> Result<InfoConfig> {
        Ok(InfoConfig {
            input: a.input,
            json: a.json,
            weld: match (a.no_weld, a.weld_tolerance) {
                (true, _) => crate::partition::Weld::Off,
                (false, Some(d)) => crate::partition::Weld::Within(d),
                (false, None) => crate::partition::Weld::Exact,
            },
        })
    }
}

/// `vcsmooth info`.
pub fn run(cfg: &InfoConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    progress.phase(format!("reading {}", cfg.input.display()));
    let mesh = crate::io::read_mesh(&cfg.input)?;
    progress.phase("measuring");
    let info = crate::engine::mesh_info(&mesh, cfg.weld).map_err(|e| e.in_file(&cfg.input))?;
    let doc = InfoDoc {
        path: cfg.input.display().to_string(),
        format: mesh.source.format.map(format_name),
        info: undefined_as_nan(&info),
        carries: mesh
            .source
            .layout
            .as_ref()
            .map(|l| l.carries())
            .unwrap_or_default(),
    };
    progress.finish();
    if cfg.json {
        print_json(out, &doc)
    } else {
        print_info(out, &doc)
    }
}

/// Print `info` as aligned `key  value` lines.
fn print_info(out: &mut dyn Write, doc: &InfoDoc) -> Result<()> {
    let i = &doc.info;
    let mut rows: Vec<(&str, String)> = vec![("file", doc.path.clone())];
    if let Some(f) = &doc.format {
        rows.push(("format", f.clone()));
    }
    rows.push(("vertices", i.vertices.to_string()));
    let faces = if i.polygons_triangulated > 0 {
        format!(
            "{} triangles from {} ({} fan-triangulated)",
            i.triangles,
            count(i.input_faces, "input face"),
            count(i.polygons_triangulated, "polygon")
        )
    } else {
        format!("{} triangles", i.triangles)
    };
    rows.push(("faces", faces));
    rows.push(("edges", i.edges.to_string()));
    rows.push(("boundary edges", i.boundary_edges.to_string()));
    rows.push(("non-manifold edges", i.non_manifold_edges.to_string()));
    rows.push(("non-manifold vertices", i.non_manifold_vertices.to_string()));
    rows.push(("degenerate triangles", i.degenerate_triangles.to_string()));
    rows.push(("orientation", orientation(i)));
    if i.high_degree_vertices > 0 {
        rows.push((
            "high-degree vertices",
            format!(
                "{} (more than {} neighbours: fixed)",
                i.high_degree_vertices,
                crate::topology::MAX_FREE_DEGREE
            ),
        ));
    }
    rows.push(("components", i.components.to_string()));
    rows.push(("unreferenced vertices", i.unreferenced_vertices.to_string()));
    rows.push((
        "welded vertices",
        match i.welded_vertices {
            0 => "0".to_string(),
            w => format!("{w} (copies of another vertex's position: smoothed as one)"),
        },
    ));
    rows.push(("closed", if i.closed { "yes" } else { "no" }.to_string()));
    rows.push(("signed volume", num(i.volume)));
    rows.push(("area", num(i.area)));
    rows.push(("bbox min", vec3(i.bbox_min)));
    rows.push(("bbox max", vec3(i.bbox_max)));
    rows.push(("bbox diagonal", num(i.bbox_diagonal)));
    rows.push(("mean edge length", num(i.mean_edge_length)));
    rows.push((
        "roughness",
        if i.roughness_deg.is_finite() {
            format!("{} deg (mean dihedral angle)", fixed(i.roughness_deg, 4))
        } else {
            format!("{UNDEFINED} (no interior edge between two triangles)")
        },
    ));
    rows.push(("carries", carried(&doc.carries)));
    print_rows(out, &rows)
}

/// What the file carries, as a list: `uvs, colours, other: vertex.confidence`.
fn carried(c: &Carried) -> String {
    let mut items: Vec<String> = [
        (c.uvs, "uvs"),
        (c.colours, "colours"),
        (c.normals, "normals (recomputed on write)"),
        (c.materials, "materials"),
    ]
    .into_iter()
    .filter(|&(has, _)| has)
    .map(|(_, name)| name.to_string())
    .collect();
    if !c.other.is_empty() {
        items.push(format!("other: {}", c.other.join(", ")));
    }
    if items.is_empty() {
        "nothing besides positions and faces".to_string()
    } else {
        items.join(", ")
    }
}

/// Whether the faces are consistently oriented, and what smoothing does about it when not.
fn orientation(i: &MeshInfo) -> String {
    if i.inconsistent_orientation_edges == 0 {
        return "consistent".to_string();
    }
    let mut s = format!(
        "inconsistent at {} (oriented consistently to measure and smooth; files keep their faces)",
        count(i.inconsistent_orientation_edges, "edge")
    );
    if i.non_orientable_components > 0 {
        s += &format!(
            "; {} non-orientable, {} fixed",
            count(i.non_orientable_components, "component"),
            count(i.orientation_seam_edges, "seam edge")
        );
    }
    s
}

/// Three coordinates, or one [`UNDEFINED`] for all of them.
fn vec3(v: [f64; 3]) -> String {
    if v.iter().all(|x| x.is_finite()) {
        format!("{} {} {}", num(v[0]), num(v[1]), num(v[2]))
    } else {
        UNDEFINED.to_string()
    }
}
