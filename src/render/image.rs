//! An RGB picture in memory, eight bits a channel, rows from the top: what the renderer draws
//! into and the PNG writer stores.

/// A red, green, blue triple.
pub type Rgb = [u8; 3];

/// White: the background of every picture.
pub const WHITE: Rgb = [255, 255, 255];
/// The colour of text and frames.
pub const INK: Rgb = [20, 20, 20];

/// `width × height` pixels, row by row from the top.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Rgb>,
}

impl Image {
    /// A picture of one colour.
    pub fn filled(width: usize, height: usize, colour: Rgb) -> Image {
        Image {
            width,
            height,
            pixels: vec![colour; width * height],
        }
    }

    /// The pixel at column `x`, row `y`.
    pub fn get(&self, x: usize, y: usize) -> Rgb {
        self.pixels[y * self.width + x]
    }

    /// Set the pixel at (`x`, `y`); a pixel outside the picture is left out (text and bars are
    /// clipped at its edges).
    pub fn set(&mut self, x: i64, y: i64, colour: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            self.pixels[y as usize * self.width + x as usize] = colour;
        }
    }

    /// Fill the rectangle of `w × h` pixels whose top left corner is (`x`, `y`), clipped.
    pub fn fill_rect(&mut self, x: i64, y: i64, w: i64, h: i64, colour: Rgb) {
        for yy in y.max(0)..(y + h).min(self.height as i64) {
            for xx in x.max(0)..(x + w).min(self.width as i64) {
                self.pixels[yy as usize * self.width + xx as usize] = colour;
            }
        }
    }

    /// The outline, one pixel wide, of the rectangle [`Image::fill_rect`] would fill.
    pub fn frame_rect(&mut self, x: i64, y: i64, w: i64, h: i64, colour: Rgb) {
        self.fill_rect(x, y, w, 1, colour);
        self.fill_rect(x, y + h - 1, w, 1, colour);
        self.fill_rect(x, y, 1, h, colour);
        self.fill_rect(x + w - 1, y, 1, h, colour);
    }

    /// Copy `other` with its top left corner at (`x`, `y`), clipped.
    pub fn paste(&mut self, other: &Image, x: i64, y: i64) {
        for oy in 0..other.height {
            let row = &other.pixels[oy * other.width..(oy + 1) * other.width];
            for (ox, &p) in row.iter().enumerate() {
                self.set(x + ox as i64, y + oy as i64, p);
            }
        }
    }

    /// The pixels as bytes, `r g b` per pixel, row by row (what a PNG of colour type RGB holds).
    pub fn rgb_bytes(&self) -> Vec<u8> {
        self.pixels.iter().flatten().copied().collect()
    }
}
