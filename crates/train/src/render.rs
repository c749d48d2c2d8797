//! Bird's-eye-view PNGs of frames: the points (grey), ground-truth boxes (green), detections (red,
//! opacity by score, the score written beside the confident ones) and the evaluation circle.
//!
//! Image axes: x (forward) points up, y (left) points left, the robot at the centre; 1 px = 2.5 cm
//! at the default 1100 px for ±27.5 m.

use std::path::Path;

use anyhow::{Context, Result, anyhow};
use data_jrdb::{Box3d, Dataset};
use image::ImageEncoder;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::plots::register_fonts;
use crate::validate::FrameResult;

/// Detections below this score are not drawn.
pub const MIN_DRAWN_SCORE: f64 = 0.05;
/// Detections at or above this score get their score written beside them.
pub const LABELLED_SCORE: f64 = 0.3;

fn pe<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("rendering: {e:?}")
}

/// Draws each frame of `frames` (points read back from `dataset`) into `dir/<sequence>_<frame>.png`.
pub fn render_frames(dataset: &Dataset, frames: &[FrameResult], dir: &Path, eval_range: Option<f64>) -> Result<()> {
    std::fs::create_dir_all(dir)?;
    for f in frames {
        let i = dataset
            .frames
            .iter()
            .position(|r| r.sequence == f.sequence && r.name == f.name)
            .with_context(|| format!("frame {}/{} is not in the dataset", f.sequence, f.name))?;
        let frame = dataset.load(i)?;
        render_bev(&frame.points, f, &dir.join(format!("{}_{}.png", f.sequence, f.name)), eval_range.unwrap_or(25.0))?;
    }
    Ok(())
}

/// Draws one frame into a PNG file.
pub fn render_bev(points: &[[f32; 3]], f: &FrameResult, path: &Path, eval_range: f64) -> Result<()> {
    let root = BitMapBackend::new(path, (SIZE, SIZE)).into_drawing_area();
    draw_bev(&root, points, f, eval_range)?;
    root.present().map_err(pe)
}

/// Draws one frame into PNG bytes (the service's `?render=1`).
pub fn render_bev_png(points: &[[f32; 3]], f: &FrameResult, eval_range: f64) -> Result<Vec<u8>> {
    let mut rgb = vec![0u8; (SIZE * SIZE * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (SIZE, SIZE)).into_drawing_area();
        draw_bev(&root, points, f, eval_range)?;
        root.present().map_err(pe)?;
    }
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(&rgb, SIZE, SIZE, image::ColorType::Rgb8)
        .map_err(|e| anyhow!("encoding the PNG: {e}"))?;
    Ok(png)
}

/// The image's side in pixels.
const SIZE: u32 = 1100;

fn draw_bev<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, points: &[[f32; 3]], f: &FrameResult, eval_range: f64) -> Result<()> {
    register_fonts();
    let size = SIZE;
    let half = eval_range + 2.5;
    let px = |x: f64, y: f64| -> (i32, i32) {
        // Forward (x) up, left (y) left.
        let u = (size as f64 / 2.0) - y / half * (size as f64 / 2.0);
        let v = (size as f64 / 2.0) - x / half * (size as f64 / 2.0);
        (u.round() as i32, v.round() as i32)
    };
    root.fill(&WHITE).map_err(pe)?;
    let grey = RGBColor(150, 150, 150);
    for p in points {
        let (u, v) = px(p[0] as f64, p[1] as f64);
        if (0..size as i32).contains(&u) && (0..size as i32).contains(&v) {
            root.draw_pixel((u, v), &grey).map_err(pe)?;
        }
    }
    let circle: Vec<(i32, i32)> = (0..=360).map(|d| (d as f64).to_radians()).map(|a| px(eval_range * a.cos(), eval_range * a.sin())).collect();
    root.draw(&PathElement::new(circle, RGBColor(90, 90, 220).stroke_width(1))).map_err(pe)?;
    let outline = |b: &Box3d| -> Vec<(i32, i32)> {
        let c = b.corners_bev();
        let mut v: Vec<(i32, i32)> = c.iter().map(|p| px(p[0], p[1])).collect();
        v.push(v[0]);
        // A heading tick from the centre to the front face.
        let front = px(b.cx + 0.5 * b.l * b.rot_z.cos(), b.cy + 0.5 * b.l * b.rot_z.sin());
        v.push(px(b.cx, b.cy));
        v.push(front);
        v
    };
    let green = RGBColor(20, 160, 40);
    for b in &f.gt {
        root.draw(&PathElement::new(outline(b), green.stroke_width(2))).map_err(pe)?;
    }
    let mut dets: Vec<_> = f.detections.iter().filter(|d| d.score >= MIN_DRAWN_SCORE).collect();
    dets.sort_by(|a, b| a.score.total_cmp(&b.score));
    for d in dets {
        let color = RGBColor(220, 30, 30).mix(d.score.clamp(0.15, 1.0));
        root.draw(&PathElement::new(outline(&d.bbox), color.stroke_width(2))).map_err(pe)?;
        if d.score >= LABELLED_SCORE {
            let (u, v) = px(d.bbox.cx, d.bbox.cy);
            root.draw(&Text::new(format!("{:.2}", d.score), (u + 8, v - 8), ("sans-serif", 13).into_font().color(&RGBColor(180, 0, 0))))
                .map_err(pe)?;
        }
    }
    let n_drawn = f.detections.iter().filter(|d| d.score >= LABELLED_SCORE).count();
    // Frames of a dataset have a sequence and labels; a user's cloud (`detect`, `serve`) has neither.
    let (name, gt) = if f.sequence.is_empty() {
        (f.name.clone(), String::new())
    } else {
        (format!("{} / {}", f.sequence, f.name), format!("   GT {} (green)", f.gt.len()))
    };
    let title = format!("{name}{gt}   detections ≥ {LABELLED_SCORE} {n_drawn} of {} (red)   circle {eval_range} m", f.detections.len());
    root.draw(&Text::new(title, (10, 10), ("sans-serif", 16).into_font())).map_err(pe)?;
    Ok(())
}
