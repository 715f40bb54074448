//! The standard views and the orthographic camera that frames a bounding box in one of them.
//!
//! The axes are those of most scans and of OpenGL: +Y up, the front seen from +Z. A camera maps a
//! point to a sample of its frame (`x` to the right, `y` down, from the top left corner) and a
//! depth in [0, 1], 0 nearest the viewer.

use glam::DVec3;

/// A direction the mesh is seen from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum View {
    /// From +Z: X to the right, Y up.
    Front,
    /// From +X: −Z to the right, Y up (the front's right side).
    Side,
    /// From +Y, looking down: X to the right, −Z up.
    Top,
    /// From (1, 1, 1), Y up: three faces of the bounding box at once.
    Iso,
}

impl View {
    /// The views of a picture, in the order its columns show them.
    pub const STANDARD: [View; 4] = [View::Front, View::Side, View::Top, View::Iso];

    /// The name a picture labels it with.
    pub fn name(self) -> &'static str {
        match self {
            View::Front => "front (+z)",
            View::Side => "side (+x)",
            View::Top => "top (+y)",
            View::Iso => "iso",
        }
    }

    /// `p` in the view's axes: along its right, its up and toward the viewer.
    #[inline]
    pub fn coordinates(self, p: DVec3) -> DVec3 {
        let (right, up, toward) = self.axes();
        DVec3::new(p.dot(right), p.dot(up), p.dot(toward))
    }

    /// The screen's right and up and the direction toward the viewer: a right-handed frame
    /// (`right × up = toward`).
    pub fn axes(self) -> (DVec3, DVec3, DVec3) {
        match self {
            View::Front => (DVec3::X, DVec3::Y, DVec3::Z),
            View::Side => (-DVec3::Z, DVec3::Y, DVec3::X),
            View::Top => (DVec3::X, -DVec3::Z, DVec3::Y),
            View::Iso => {
                let toward = DVec3::ONE.normalize();
                let up = (DVec3::Y - toward * toward.y).normalize();
                (up.cross(toward), up, toward)
            }
        }
    }
}

/// An axis-aligned box; `Bounds::EMPTY` holds nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    pub min: DVec3,
    pub max: DVec3,
}

impl Bounds {
    pub const EMPTY: Bounds = Bounds {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    /// The box holding both.
    pub fn union(self, other: Bounds) -> Bounds {
        Bounds {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    pub fn is_empty(&self) -> bool {
        !(self.min.cmple(self.max).all())
    }

    /// The box of `points` in the axes of `view` ([`View::coordinates`]): what a camera of that
    /// view frames.
    pub fn in_view(points: &[DVec3], view: View) -> Bounds {
        let (right, up, toward) = view.axes();
        points.iter().fold(Bounds::EMPTY, |b, &p| {
            let q = DVec3::new(p.dot(right), p.dot(up), p.dot(toward));
            Bounds {
                min: b.min.min(q),
                max: b.max.max(q),
            }
        })
    }
}

/// Share of a frame's shorter side the framed box may take: a margin all round.
const FILL: f64 = 0.9;

/// An orthographic camera over a frame of `width × height` samples: `x = p·sx + ox`,
/// `y = p·sy + oy`, `depth = p·sz + oz`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub view: View,
    pub width: usize,
    pub height: usize,
    /// Toward the viewer (the headlight's direction).
    pub toward: DVec3,
    sx: DVec3,
    sy: DVec3,
    sz: DVec3,
    offset: DVec3,
}

impl Camera {
    /// The camera of `view` that shows all of `seen` (a box in the view's axes, see
    /// [`Bounds::in_view`]) centred in a `width × height` frame, as large as fits with a margin;
    /// its depths span the box's with half its depth again on each side, for points that moved out
    /// of it. An empty or point-like box gets a unit scale.
    pub fn framing(view: View, seen: Bounds, width: usize, height: usize) -> Camera {
        let (right, up, toward) = view.axes();
        let (lo, hi) = match seen.is_empty() {
            true => (DVec3::ZERO, DVec3::ZERO),
            false => (seen.min, seen.max),
        };
        let extent = hi - lo;
        let fit = |side: usize, ext: f64| match ext > 0.0 {
            true => FILL * side as f64 / ext,
            false => f64::INFINITY,
        };
        let mut scale = fit(width, extent.x).min(fit(height, extent.y));
        if !scale.is_finite() {
            scale = 1.0;
        }
        let centre = (lo + hi) * 0.5;
        let depth = extent
            .z
            .max(extent.x.max(extent.y) * 1e-3)
            .max(f64::MIN_POSITIVE);
        let (near, far) = (hi.z + depth * 0.5, lo.z - depth * 0.5);
        Camera {
            view,
            width,
            height,
            toward,
            sx: right * scale,
            sy: -up * scale,
            sz: -toward / (near - far),
            offset: DVec3::new(
                width as f64 * 0.5 - centre.x * scale,
                height as f64 * 0.5 + centre.y * scale,
                near / (near - far),
            ),
        }
    }

    /// The same camera over a frame `factor` times as wide and high (the samples of a picture
    /// drawn at `factor²` samples a pixel).
    pub fn scaled(&self, factor: usize) -> Camera {
        let f = factor as f64;
        Camera {
            width: self.width * factor,
            height: self.height * factor,
            sx: self.sx * f,
            sy: self.sy * f,
            offset: DVec3::new(self.offset.x * f, self.offset.y * f, self.offset.z),
            ..*self
        }
    }

    /// The maps of a point to its sample column and row, as [`Camera::project`] applies them:
    /// `[(sx, ox), (sy, oy)]`, `x = p·sx + ox`, `y = p·sy + oy`.
    pub fn screen(&self) -> [(DVec3, f64); 2] {
        [(self.sx, self.offset.x), (self.sy, self.offset.y)]
    }

    /// `p` in frame coordinates: sample column, row (continuous, sample centres at `k + ½`) and
    /// depth.
    #[inline]
    pub fn project(&self, p: DVec3) -> DVec3 {
        DVec3::new(p.dot(self.sx), p.dot(self.sy), p.dot(self.sz)) + self.offset
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_views_are_right_handed_and_orthonormal() {
        for v in View::STANDARD {
            let (r, u, t) = v.axes();
            assert!((r.cross(u) - t).length() < 1e-12, "{v:?}");
            assert!(
                (r.length() - 1.0).abs() < 1e-12 && r.dot(u).abs() < 1e-12,
                "{v:?}"
            );
        }
    }

    #[test]
    fn a_framed_box_is_centred_with_its_margin() {
        let corners = [DVec3::new(-1.0, -2.0, -3.0), DVec3::new(1.0, 2.0, 3.0)];
        let b = Bounds::in_view(&corners, View::Front);
        let c = Camera::framing(View::Front, b, 200, 100);
        // 4 units of height fill 90 of 100 rows: 22.5 samples a unit.
        let top = c.project(DVec3::new(-1.0, 2.0, 3.0));
        assert!((top.x - (100.0 - 22.5)).abs() < 1e-9, "{top}");
        assert!((top.y - 5.0).abs() < 1e-9, "{top}");
        let near = c.project(DVec3::new(0.0, 0.0, 3.0)).z;
        let far = c.project(DVec3::new(0.0, 0.0, -3.0)).z;
        assert!(near > 0.0 && near < far && far < 1.0, "{near} {far}");
        let s = c.scaled(3);
        let p = s.project(DVec3::new(-1.0, 2.0, 3.0));
        assert!((p.x - 3.0 * top.x).abs() < 1e-9 && (p.z - top.z).abs() < 1e-12);
    }
}
