//! `figure.fdm_photo_overlay`: each photo of an `fdm-photos` dataset with the widths
//! `fdm.measure_photos` measured drawn on it, as a reader checks them: every measured
//! position's left edge in red and right edge in green, and where the bead is broken (a
//! gap, width 0) the G-code's axis in blue. The points come from `photo_widths.parquet`,
//! already in photo pixels; the photo is drawn as it is, at full size.

use pipeline::params::NoParams;
use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::{photo_calibration as cal_t, photo_widths as widths_t};

use crate::read::{f64s, read_parquet, strs};

/// The `figure.fdm_photo_overlay` stage kind.
pub struct PhotoOverlayFigure;

/// The measured widths and where each photo is.
const MEASURED: Input = Input::one(
    "measured",
    &[Source::Stage("fdm.measure_photos")],
    "widths measured from photos (`photo_widths`, `photo_calibration`)",
)
.reading(&[
    Reads {
        table: &widths_t::TABLE,
        columns: &[
            widths_t::photo_id,
            widths_t::width_mm,
            widths_t::axis_x_px,
            widths_t::axis_y_px,
            widths_t::left_x_px,
            widths_t::left_y_px,
            widths_t::right_x_px,
            widths_t::right_y_px,
        ],
    },
    Reads { table: &cal_t::TABLE, columns: &[cal_t::photo_id, cal_t::image, cal_t::status] },
]);

/// The photos themselves.
const PHOTOS: Input = Input::one(
    "photos",
    &[Source::Stage("fdm.import_photos"), Source::Dataset("fdm-photos")],
    "the photographed print (`fdm-photos`)",
);

/// Colours of the left edge, the right edge and a gap's axis.
const LEFT: [u8; 3] = [255, 40, 40];
const RIGHT: [u8; 3] = [40, 230, 40];
const GAP: [u8; 3] = [40, 120, 255];

impl Stage for PhotoOverlayFigure {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_photo_overlay",
        version: 1,
        summary: "Each photo with its measured edges (red left, green right) and gaps (blue) drawn on it → overlay_<photo_id>.png",
        implements: "paper 000 Sec. III (widths from camera images), checked on the photo",
        inputs: &[MEASURED, PHOTOS],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let measured = ctx.input(&MEASURED).dir.clone();
        let photos = ctx.input(&PHOTOS).dir.clone();
        let cal_path = measured.join(cal_t::TABLE.file());
        let cal = read_parquet(&cal_path)?;
        let (ids, images, status) = (
            strs(&cal, cal_t::photo_id, &cal_path)?,
            strs(&cal, cal_t::image, &cal_path)?,
            strs(&cal, cal_t::status, &cal_path)?,
        );
        let points = Points::read(&measured.join(widths_t::TABLE.file()))?;
        for k in (0..ids.len()).filter(|&k| status[k] == "calibrated") {
            let file = photos.join(&images[k]);
            let bytes = std::fs::read(&file).map_err(|e| StageError::io(&file, e))?;
            let mut photo = image::load_from_memory(&bytes)
                .map_err(|e| StageError::BadInput {
                    file: file.clone(),
                    location: None,
                    expected: format!("a JPEG or PNG photo: {e}"),
                })?
                .into_rgb8();
            points.draw(&ids[k], &mut photo);
            let out = ctx.output_path(&format!("overlay_{}.png", ids[k]))?;
            photo.save(&out).map_err(|e| StageError::io(&out, std::io::Error::other(e.to_string())))?;
        }
        Ok(())
    }
}

/// The photo points of every measured position.
struct Points {
    photo_id: Vec<String>,
    width_mm: Vec<f64>,
    xy: [Vec<f64>; 6],
}

impl Points {
    fn read(path: &std::path::Path) -> Result<Self, StageError> {
        let df = read_parquet(path)?;
        let columns = [
            widths_t::axis_x_px,
            widths_t::axis_y_px,
            widths_t::left_x_px,
            widths_t::left_y_px,
            widths_t::right_x_px,
            widths_t::right_y_px,
        ];
        let mut xy: [Vec<f64>; 6] = Default::default();
        for (k, c) in columns.iter().enumerate() {
            xy[k] = f64s(&df, c, path)?;
        }
        Ok(Self { photo_id: strs(&df, widths_t::photo_id, path)?, width_mm: f64s(&df, widths_t::width_mm, path)?, xy })
    }

    fn draw(&self, photo_id: &str, photo: &mut image::RgbImage) {
        for i in (0..self.photo_id.len()).filter(|&i| self.photo_id[i] == photo_id) {
            if self.width_mm[i] > 0.0 {
                put(photo, self.xy[2][i], self.xy[3][i], LEFT);
                put(photo, self.xy[4][i], self.xy[5][i], RIGHT);
            } else {
                put(photo, self.xy[0][i], self.xy[1][i], GAP);
            }
        }
    }
}

/// Colours the pixel holding (x, y) (px, the top-left pixel's corner at 0, 0), if inside.
fn put(photo: &mut image::RgbImage, x: f64, y: f64, colour: [u8; 3]) {
    if x.is_finite()
        && y.is_finite()
        && x >= 0.0
        && y >= 0.0
        && (x as u32) < photo.width()
        && (y as u32) < photo.height()
    {
        photo.put_pixel(x as u32, y as u32, image::Rgb(colour));
    }
}
