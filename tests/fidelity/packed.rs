//! Files as other tools pack them (see tests/fidelity.rs): a gzip-compressed scan, as the Stanford
//! repository ships them, and a scan stored as triangle strips (`tests/data/formats`, see its
//! PROVENANCE.md). Each is smoothed as the plain mesh it holds and written back in its own form.

use std::io::Read;
use std::path::Path;

use vcsmooth::io;

use crate::util::{arg, fails, ok, scan, vcsmooth};

fn gunzip(path: &Path) -> Vec<u8> {
    let mut out = Vec::new();
    flate2::read::MultiGzDecoder::new(std::fs::File::open(path).unwrap())
        .read_to_end(&mut out)
        .unwrap();
    out
}

#[test]
fn a_gzipped_scan_smooths_as_the_scan_it_holds() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let packed = scan("formats/fertility-9k.ply.gz");
    ok(vcsmooth([
        "smooth",
        &arg(&scan("fertility-9k.ply")),
        &arg(&d("plain.ply")),
    ]));
    let plain = std::fs::read(d("plain.ply")).unwrap();
    ok(vcsmooth(["smooth", &arg(&packed), &arg(&d("from-gz.ply"))]));
    assert_eq!(std::fs::read(d("from-gz.ply")).unwrap(), plain);

    // Compressed output when asked, in every format that can be: the same bytes inside.
    ok(vcsmooth(["smooth", &arg(&packed), &arg(&d("out.ply.gz"))]));
    assert_eq!(&std::fs::read(d("out.ply.gz")).unwrap()[..2], b"\x1f\x8b");
    assert_eq!(gunzip(&d("out.ply.gz")), plain);
    ok(vcsmooth(["smooth", &arg(&packed), &arg(&d("out.obj"))]));
    ok(vcsmooth(["smooth", &arg(&packed), &arg(&d("out.OBJ.GZ"))]));
    assert_eq!(
        gunzip(&d("out.OBJ.GZ")),
        std::fs::read(d("out.obj")).unwrap()
    );
    // And read back as what they hold.
    let back = io::read_mesh(&d("out.OBJ.GZ")).unwrap();
    assert_eq!(
        back.positions[..],
        io::read_mesh(&d("out.obj")).unwrap().positions[..]
    );

    let info = ok(vcsmooth(["info", &arg(&packed)]));
    assert!(info.contains("vertices               4494"), "{info}");

    // A glTF output is never compressed: refused before anything is read.
    let out = vcsmooth(["smooth", &arg(&packed), &arg(&d("out.glb.gz"))]);
    fails(&out, 2, &["out.glb.gz", "drop the .gz"]);
    assert!(!d("out.glb.gz").exists());
}

#[test]
fn a_damaged_gzip_file_is_one_line_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(scan("formats/fertility-9k.ply.gz")).unwrap();
    let cut = dir.path().join("cut.ply.gz");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let out = vcsmooth(["smooth", &arg(&cut), &arg(&dir.path().join("o.ply"))]);
    fails(&out, 1, &["cut.ply.gz: gzip data ends early"]);
    let mut flipped = bytes.clone();
    let n = flipped.len();
    flipped[n - 6] ^= 0xff; // the CRC of the data
    let bad = dir.path().join("bad.ply.gz");
    std::fs::write(&bad, &flipped).unwrap();
    let out = vcsmooth(["smooth", &arg(&bad), &arg(&dir.path().join("o.ply"))]);
    fails(&out, 1, &["bad.ply.gz: gzip data is damaged"]);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
}

#[test]
fn triangle_strips_are_read_smoothed_and_written_back_as_strips() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let strips = scan("formats/igea-strips-part.ply");
    let input = std::fs::read(&strips).unwrap();
    // 6,079 triangles, as counted when the part was cut (PROVENANCE.md), all one way round.
    let info = ok(vcsmooth(["info", &arg(&strips)]));
    for line in [
        "vertices               5210",
        "faces                  6079 triangles",
        "non-manifold edges     0",
        "orientation            consistent",
    ] {
        assert!(info.contains(line), "{line} not in:\n{info}");
    }

    ok(vcsmooth(["smooth", &arg(&strips), &arg(&d("out.ply"))]));
    let output = std::fs::read(d("out.ply")).unwrap();
    // The same header and the same strips record: only the vertex block changed.
    let body = input
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let vertices_end = body + 5210 * 12;
    assert_eq!(output.len(), input.len());
    assert_eq!(output[..body], input[..body]);
    assert_eq!(output[vertices_end..], input[vertices_end..]);
    assert_ne!(output[body..vertices_end], input[body..vertices_end]);

    // The strips smoothed as the same triangles written as faces.
    let mut plain = io::read_mesh(&strips).unwrap();
    plain.source = Default::default();
    io::write_mesh(&d("faces.ply"), &plain).unwrap();
    ok(vcsmooth([
        "smooth",
        &arg(&d("faces.ply")),
        &arg(&d("faces-out.ply")),
    ]));
    let from_faces = io::read_mesh(&d("faces-out.ply")).unwrap();
    let from_strips = io::read_mesh(&d("out.ply")).unwrap();
    assert_eq!(from_strips.triangles[..], plain.triangles[..]);
    assert_eq!(from_strips.positions[..], from_faces.positions[..]);
}

/// `torus_box.glb` (tests/data/formats): its torus's UV seam duplicates a ring of vertices whose
/// positions, computed at angle 2π instead of 0, differ in the last bits. Exact welding leaves
/// that seam a boundary that never moves; a tolerance welds it, every vertex moves, and the
/// texture coordinates stay as they were.
#[test]
fn a_uv_seam_rounded_apart_is_welded_within_a_tolerance() {
    let dir = tempfile::tempdir().unwrap();
    let input = scan("formats/torus_box.glb");
    let boundary = |extra: &[&str]| {
        let mut args = vec!["info".to_string(), arg(&input), "--json".into()];
        args.extend(extra.iter().map(|s| s.to_string()));
        let doc = crate::util::json(&ok(vcsmooth(args)));
        doc["boundary_edges"].as_u64().unwrap()
    };
    assert_eq!(boundary(&[]), 160);
    assert_eq!(boundary(&["--weld-tolerance", "1e-5"]), 0);
    let before = io::read_mesh(&input).unwrap();
    let moved = |extra: &[&str]| {
        let out = dir.path().join("out.glb");
        let mut args = vec!["smooth".to_string(), arg(&input), arg(&out)];
        args.extend(extra.iter().map(|s| s.to_string()));
        ok(vcsmooth(args));
        let after = io::read_mesh(&out).unwrap();
        // Only POSITION and NORMAL are rewritten: the UVs are the input's.
        let uvs = |path: &Path| {
            let (json, bin) = super::gltf::unglb(&std::fs::read(path).unwrap());
            super::draco::elements(&json, &bin, super::draco::attribute(&json, 0, "TEXCOORD_0"))
        };
        assert_eq!(uvs(&out), uvs(&input));
        before
            .positions
            .iter()
            .zip(after.positions.iter())
            .filter(|(a, b)| a != b)
            .count()
    };
    let n = before.positions.len();
    assert!(moved(&[]) < n - 100, "exact welding leaves the seam");
    assert_eq!(moved(&["--weld-tolerance", "1e-5"]), n);
}

/// `subdivide` and `generate` write plain glTF as `smooth` does, and gzip where asked.
#[test]
fn subdivide_and_generate_write_glb_and_gz() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    ok(vcsmooth([
        "subdivide",
        &arg(&scan("fertility-9k.ply")),
        &arg(&d("sub.glb")),
        "--max-edge",
        "4",
    ]));
    ok(vcsmooth([
        "subdivide",
        &arg(&scan("fertility-9k.ply")),
        &arg(&d("sub.ply.gz")),
        "--max-edge",
        "4",
    ]));
    let (glb, gz) = (
        io::read_mesh(&d("sub.glb")).unwrap(),
        io::read_mesh(&d("sub.ply.gz")).unwrap(),
    );
    assert!(glb.triangles.len() > 9000);
    assert_eq!(glb.triangles[..], gz.triangles[..]);
    assert_eq!(glb.positions[..], gz.positions[..]);
    ok(vcsmooth([
        "generate",
        "sphere",
        &arg(&d("g.glb")),
        "--subdivisions",
        "3",
    ]));
    assert_eq!(io::read_mesh(&d("g.glb")).unwrap().triangles.len(), 1280);
}
