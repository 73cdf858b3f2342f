//! The studio (egui).
