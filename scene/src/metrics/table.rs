//! Per-object and overall metric tables: accumulates each object's error
//! lists (a miss is an infinite error) and summarises them as the YCB-Video
//! ADD-S AUC, ADD(S) AUC and ADD-S < 2 cm, in percent.

use std::collections::BTreeMap;
use std::fmt;

use serde::Serialize;

use super::PoseErrors;
use super::accuracy::{ADD_S_THRESHOLD_2CM, accuracy_below_percent, vocap_auc_percent};
use crate::ObjectSet;

/// One summary row (all percentages 0..100).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MetricsRow {
    /// The class id; `None` for the overall row.
    pub class_id: Option<u16>,
    pub name: String,
    /// ADD-S AUC up to 0.1 m, percent.
    pub add_s_auc: f64,
    /// ADD(S) AUC up to 0.1 m (ADD for asymmetric, ADD-S for symmetric objects), percent.
    pub add_s_auc_symmetric_aware: f64,
    /// Share of ADD-S errors below 2 cm, percent.
    pub add_s_lt_2cm: f64,
    /// Number of scored ground-truth instances (misses included).
    pub count: usize,
}

#[derive(Clone, Debug, Default)]
struct ObjectErrors {
    name: String,
    add_s: Vec<f64>,
    add_or_add_s: Vec<f64>,
}

/// Accumulates per-object ADD-S and ADD(S) error lists (metres).
///
/// Rows are ordered by class id. The overall row pools every instance of
/// every object (as the "ALL" column of the YCB-Video results does).
#[derive(Clone, Debug, Default)]
pub struct MetricsTable {
    objects: BTreeMap<u16, ObjectErrors>,
}

impl MetricsTable {
    /// A table with a row, possibly empty, for each `(class id, name)`.
    pub fn new(classes: impl IntoIterator<Item = (u16, String)>) -> Self {
        let objects = classes.into_iter().map(|(id, name)| (id, ObjectErrors { name, ..Default::default() })).collect();
        Self { objects }
    }

    /// A table with a row for every object of `set` (class id `i + 1`).
    pub fn for_objects(set: &ObjectSet) -> Self {
        Self::new(set.objects.iter().enumerate().map(|(i, o)| (i as u16 + 1, o.name.clone())))
    }

    fn entry(&mut self, class_id: u16) -> &mut ObjectErrors {
        self.objects
            .entry(class_id)
            .or_insert_with(|| ObjectErrors { name: format!("class_{class_id}"), ..Default::default() })
    }

    /// Records one ground-truth instance of `class_id`: its errors, or `None`
    /// when the estimator missed it (scored as an infinite error). A class id
    /// not named at construction gets a row named `class_<id>`.
    pub fn record(&mut self, class_id: u16, errors: Option<PoseErrors>) {
        let e = self.entry(class_id);
        match errors {
            Some(p) => {
                e.add_s.push(p.add_s);
                e.add_or_add_s.push(p.add_or_add_s);
            }
            None => {
                e.add_s.push(f64::INFINITY);
                e.add_or_add_s.push(f64::INFINITY);
            }
        }
    }

    /// Records a missed instance of `class_id`.
    pub fn record_miss(&mut self, class_id: u16) {
        self.record(class_id, None);
    }

    /// Adds every instance recorded in `other` (for evaluation split across workers).
    pub fn merge(&mut self, other: &MetricsTable) {
        for (&id, o) in &other.objects {
            let e =
                self.objects.entry(id).or_insert_with(|| ObjectErrors { name: o.name.clone(), ..Default::default() });
            e.add_s.extend_from_slice(&o.add_s);
            e.add_or_add_s.extend_from_slice(&o.add_or_add_s);
        }
    }

    /// The ADD-S errors recorded for `class_id` (metres; misses are infinite).
    pub fn add_s_errors(&self, class_id: u16) -> &[f64] {
        self.objects.get(&class_id).map(|e| e.add_s.as_slice()).unwrap_or(&[])
    }

    /// The ADD(S) errors recorded for `class_id` (metres; misses are infinite).
    pub fn add_or_add_s_errors(&self, class_id: u16) -> &[f64] {
        self.objects.get(&class_id).map(|e| e.add_or_add_s.as_slice()).unwrap_or(&[])
    }

    /// `(name, ADD-S errors)` per object, for accuracy-curve plots.
    pub fn add_s_curves(&self) -> Vec<(String, Vec<f64>)> {
        self.objects.values().map(|e| (e.name.clone(), e.add_s.clone())).collect()
    }

    fn summarise(class_id: Option<u16>, name: &str, add_s: &[f64], add_or_add_s: &[f64]) -> MetricsRow {
        MetricsRow {
            class_id,
            name: name.to_string(),
            add_s_auc: vocap_auc_percent(add_s),
            add_s_auc_symmetric_aware: vocap_auc_percent(add_or_add_s),
            add_s_lt_2cm: accuracy_below_percent(add_s, ADD_S_THRESHOLD_2CM),
            count: add_s.len(),
        }
    }

    /// One row per object, by class id.
    pub fn rows(&self) -> Vec<MetricsRow> {
        self.objects.iter().map(|(&id, e)| Self::summarise(Some(id), &e.name, &e.add_s, &e.add_or_add_s)).collect()
    }

    /// The row pooling all instances of all objects, named `ALL`.
    pub fn overall(&self) -> MetricsRow {
        let add_s: Vec<f64> = self.objects.values().flat_map(|e| e.add_s.iter().copied()).collect();
        let add_or: Vec<f64> = self.objects.values().flat_map(|e| e.add_or_add_s.iter().copied()).collect();
        Self::summarise(None, "ALL", &add_s, &add_or)
    }

    /// `{"objects": [row, ...], "overall": row}`; each row has `class_id`,
    /// `name`, `add_s_auc`, `add_s_auc_symmetric_aware`, `add_s_lt_2cm`
    /// (percent) and `count`.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({ "objects": self.rows(), "overall": self.overall() })
    }
}

impl fmt::Display for MetricsTable {
    /// An aligned text table, one line per object then `ALL`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut rows = self.rows();
        rows.push(self.overall());
        let name_w = rows.iter().map(|r| r.name.chars().count()).max().unwrap_or(0).max("object".len());
        writeln!(
            f,
            "{:>3}  {:<name_w$}  {:>9}  {:>11}  {:>10}  {:>6}",
            "id", "object", "ADD-S AUC", "ADD(S) AUC", "ADD-S<2cm", "count"
        )?;
        for r in &rows {
            let id = r.class_id.map(|i| i.to_string()).unwrap_or_default();
            writeln!(
                f,
                "{:>3}  {:<name_w$}  {:>9.2}  {:>11.2}  {:>10.2}  {:>6}",
                id, r.name, r.add_s_auc, r.add_s_auc_symmetric_aware, r.add_s_lt_2cm, r.count
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn errs(add: f64, add_s: f64, symmetric: bool) -> Option<PoseErrors> {
        Some(PoseErrors { add, add_s, add_or_add_s: if symmetric { add_s } else { add } })
    }

    fn table() -> MetricsTable {
        let mut t = MetricsTable::new(vec![(1, "mug".to_string()), (2, "bowl".to_string())]);
        // mug (asymmetric): ADD-S [0, 0.05] -> 100; ADD(S)=ADD [0.05, 0.05] -> 75.
        t.record(1, errs(0.05, 0.0, false));
        t.record(1, errs(0.05, 0.05, false));
        // bowl (symmetric): ADD-S [0.01, miss] -> (.01*.5 + .09*.5)*10 = 50.
        t.record(2, errs(0.3, 0.01, true));
        t.record_miss(2);
        t
    }

    #[test]
    fn rows_hold_hand_computed_values() {
        let rows = table().rows();
        assert_eq!(rows.len(), 2);
        let mug = &rows[0];
        assert_eq!((mug.class_id, mug.name.as_str(), mug.count), (Some(1), "mug", 2));
        assert!((mug.add_s_auc - 100.0).abs() < 1e-9);
        assert!((mug.add_s_auc_symmetric_aware - 75.0).abs() < 1e-9);
        assert!((mug.add_s_lt_2cm - 50.0).abs() < 1e-9);
        let bowl = &rows[1];
        assert!((bowl.add_s_auc - 50.0).abs() < 1e-9);
        assert!((bowl.add_s_auc_symmetric_aware - 50.0).abs() < 1e-9);
        assert!((bowl.add_s_lt_2cm - 50.0).abs() < 1e-9);
    }

    #[test]
    fn overall_pools_all_instances() {
        // ADD-S pooled: [0, .01, .05, inf], n = 4, prec .25 .5 .75:
        // mrec [0 0 .01 .05 .1], mpre [0 .25 .5 .75 .75]:
        // .01*.5 + .04*.75 + .05*.75 = .0725 -> 72.5 %.
        let all = table().overall();
        assert_eq!(all.count, 4);
        assert_eq!(all.class_id, None);
        assert!((all.add_s_auc - 72.5).abs() < 1e-9, "{}", all.add_s_auc);
        // ADD(S) pooled: [.05 .05 .01 inf] -> sorted [.01 .05 .05 inf]:
        // mrec [0 .01 .05 .05 .1], mpre [0 .25 .5 .75 .75]:
        // .01*.25 + .04*.5 + .05*.75 = .06 -> 60 %.
        assert!((all.add_s_auc_symmetric_aware - 60.0).abs() < 1e-9);
        assert!((all.add_s_lt_2cm - 50.0).abs() < 1e-9);
    }

    #[test]
    fn json_has_the_documented_keys() {
        let v = table().to_json();
        let all = &v["overall"];
        for key in ["add_s_auc", "add_s_auc_symmetric_aware", "add_s_lt_2cm", "count"] {
            assert!(all.get(key).is_some(), "missing {key}");
        }
        assert_eq!(v["objects"][1]["name"], "bowl");
        assert_eq!(v["objects"][1]["count"], 2);
    }

    #[test]
    fn text_table_is_aligned() {
        let text = table().to_string();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4);
        assert!(lines.iter().all(|l| l.len() == lines[0].len()), "{text}");
        assert!(lines[3].contains("ALL"));
    }

    #[test]
    fn unknown_classes_and_merges() {
        let mut a = MetricsTable::default();
        a.record(7, errs(0.0, 0.0, false));
        let mut b = table();
        b.merge(&a);
        assert_eq!(b.rows().len(), 3);
        assert_eq!(b.rows()[2].name, "class_7");
        assert_eq!(b.overall().count, 5);
        assert_eq!(b.add_s_errors(2)[1], f64::INFINITY);
    }
}
