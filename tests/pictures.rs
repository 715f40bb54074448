//! `--png`: `smooth` and `compare` draw what the smoothing did; the picture is a real
//! PNG of the size the run prints, the same for any thread count, and changes nothing else.

use std::path::Path;

use crate::util::*;

/// Width, height and the RGB(A) samples of a PNG.
fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
    let bytes = std::fs::read(path).unwrap();
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let frame = reader.next_frame(&mut buf).unwrap();
    buf.truncate(frame.buffer_size());
    (frame.width, frame.height, buf)
}

/// The distinct colours of an 8-bit RGB or RGBA image.
fn colours(samples: &[u8], channels: usize) -> usize {
    let mut seen: Vec<&[u8]> = samples.chunks(channels).collect();
    seen.sort_unstable();
    seen.dedup();
    seen.len()
}

fn noisy() -> std::path::PathBuf {
    root().join("tests/data/denoising/Fandisk0.3-noisy.ply")
}

#[test]
fn smooth_draws_the_run_and_changes_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    // Each run in its own folder under the same names: the picture's labels name the files.
    let run = |name: &str, extra: &[&str]| {
        std::fs::create_dir_all(dir.path().join(name)).unwrap();
        let out = dir.path().join(name).join("out.ply");
        let mut args = vec![
            "smooth".to_string(),
            arg(&noisy()),
            arg(&out),
            "--iterations".into(),
            "3".into(),
            "--patch-size".into(),
            "2000".into(),
        ];
        args.extend(extra.iter().map(|a| a.to_string()));
        let text = ok(vcsmooth(&args));
        (std::fs::read(&out).unwrap(), text)
    };
    let (p1, p2) = (dir.path().join("t1.png"), dir.path().join("t2.png"));
    let again = dir.path().join("again").join("t1.png");
    let (plain, _) = run("plain", &["--threads", "1"]);
    let (one, text) = run("one", &["--threads", "1", "--png", &arg(&p1)]);
    let (two, _) = run(
        "two",
        &["--threads", "2", "--png", &arg(&p2), "--png-size", "200"],
    );
    assert!(
        one == plain && two == plain,
        "--png changed the smoothed mesh"
    );
    let (w, h, samples) = decode(&p1);
    let line = text.lines().find(|l| l.starts_with("picture: ")).unwrap();
    assert!(
        line.contains(&format!("{w} x {h} pixels")),
        "{line} but {w} x {h}"
    );
    // Three rows of four views (before, after, coloured by the signed deviation): far more than a
    // blank sheet's colours, and the colour map's too.
    let channels = samples.len() / (w * h) as usize;
    assert!(
        colours(&samples, channels) > 1000,
        "{} colours",
        colours(&samples, channels)
    );
    // The deviation is signed: the map shows vertices moved inwards (blue) and outwards (red).
    let pixels: Vec<&[u8]> = samples.chunks(channels).collect();
    let blue = pixels
        .iter()
        .filter(|p| p[2] as i32 > p[0] as i32 + 60)
        .count();
    // (Red: no shade of grey nor of the sequential map, whose warm end is yellow.)
    let red = pixels
        .iter()
        .filter(|p| p[0] as i32 > p[1] as i32 + 60 && p[0] as i32 > p[2] as i32 + 60)
        .count();
    assert!(blue > 1000 && red > 1000, "{blue} blue, {red} red pixels");
    // Smaller tiles, a smaller picture; and the same picture for any thread count.
    let (w2, h2, _) = decode(&p2);
    assert!(w2 < w && h2 < h, "{w2} x {h2} against {w} x {h}");
    run("again", &["--threads", "2", "--png", &arg(&again)]);
    assert!(std::fs::read(&again).unwrap() == std::fs::read(&p1).unwrap());
}

#[test]
fn a_picture_never_takes_the_place_of_an_input() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    std::fs::copy(noisy(), &input).unwrap();
    let before = std::fs::read(&input).unwrap();
    let out = dir.path().join("out.ply");
    // A picture's name ends in .png, which no mesh's does: the input is refused as one.
    let o = vcsmooth(["smooth", &arg(&input), &arg(&out), "--png", &arg(&input)]);
    fails(&o, 2, &["in.ply", ".png"]);
    // And a picture already there is only replaced by a run that names it.
    let kept = dir.path().join("kept.png");
    std::fs::write(&kept, b"not mine").unwrap();
    let o = vcsmooth(["smooth", &arg(&input), &arg(&kept), "--png", &arg(&kept)]);
    assert_ne!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(std::fs::read(&kept).unwrap(), b"not mine");
    assert!(std::fs::read(&input).unwrap() == before);
    assert!(!out.exists());
}

#[test]
fn compare_draws_both_meshes_and_their_distances() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.ply");
    ok(vcsmooth([
        "smooth",
        &arg(&noisy()),
        &arg(&out),
        "--iterations",
        "2",
    ]));
    for extra in [&[][..], &["--surface"][..]] {
        let png = dir.path().join(format!("c{}.png", extra.len()));
        let mut args = vec![
            "compare".to_string(),
            arg(&noisy()),
            arg(&out),
            "--png".into(),
        ];
        args.push(arg(&png));
        args.extend(extra.iter().map(|a| a.to_string()));
        let text = ok(vcsmooth(&args));
        assert!(text.contains("picture: "), "{text}");
        let (w, h, samples) = decode(&png);
        let channels = samples.len() / (w * h) as usize;
        assert!(colours(&samples, channels) > 1000, "{extra:?}");
    }
}

/// A picture is drawn by the engine of one process: with `--checkpoint` (the cluster engine) it
/// is refused before any work, naming the flag, and nothing is written.
#[test]
fn a_picture_of_a_cluster_run_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let input = noisy();
    let (out, png, work) = (
        dir.path().join("out.ply"),
        dir.path().join("p.png"),
        dir.path().join("work"),
    );
    let o = vcsmooth([
        "smooth",
        &arg(&input),
        &arg(&out),
        "--png",
        &arg(&png),
        "--checkpoint",
        &arg(&work),
    ]);
    fails(&o, 2, &["--png", "--checkpoint"]);
    assert!(listing(dir.path()).is_empty(), "{:?}", listing(dir.path()));
}
