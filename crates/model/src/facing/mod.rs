//! A second stage that tells which way a detected person faces, from the points in the box.
//!
//! IoU does not see a heading's direction (a box turned by 180° is the same box), and no recipe
//! of the network learned it on the simulated benchmark (docs/recipe.md §14), while a linear read
//! of the points' occupancy in the box's frame tells it for most people. This stage keeps the
//! detector's box and axis and only chooses the direction along the axis: towards the sensor's
//! side or away from it. It is fitted per run (`train facing`) on the detector's own boxes over
//! the training split and stored beside the checkpoints (`facing.json`).
//!
//! - [`features`]: the box's frame (axis signed towards the sensor) and the occupancy histogram.
//! - [`logistic`]: L2-regularised logistic regression, fitted by damped Newton steps.
//! - [`classifier`]: [`FacingClassifier`], the two together: fit, probability, orient.

/// The two together: what a run stores and applies.
pub mod classifier;
/// The box's frame and the occupancy histogram in it.
pub mod features;
/// Logistic regression.
pub mod logistic;

pub use classifier::{FacingClassifier, FacingSample};
pub use features::{FacingFeatures, faces_along_axis};
pub use logistic::LogisticRegression;
