//! `results.json`: the settings that decide correctness, then one object a result with the summary
//! file's columns as keys (fractions with every digit) and its thresholds under `ratio_test`.

use serde::Serialize;

use crate::results::{PairResult, SummaryRow};

/// The whole document.
#[derive(Serialize)]
struct Document<'a> {
    tolerance_px: f64,
    clatch_settings: &'a str,
    results: Vec<ResultObject>,
}

/// One method on one pair.
#[derive(Serialize)]
struct ResultObject {
    #[serde(flatten)]
    summary: SummaryRow<Option<f64>, Option<f64>>,
    ratio_test: Vec<ThresholdObject>,
}

/// The ratio test at one threshold.
#[derive(Serialize)]
struct ThresholdObject {
    ratio: f32,
    kept: usize,
    correct_kept: usize,
    precision: Option<f64>,
    recall: Option<f64>,
}

/// The JSON text of `results`.
pub fn to_json(results: &[PairResult], tolerance: f64, settings: &str) -> String {
    let document = Document {
        tolerance_px: tolerance,
        clatch_settings: settings,
        results: results
            .iter()
            .map(|r| ResultObject {
                summary: r.summary_row(|v| v, |v| v),
                ratio_test: r
                    .curve
                    .iter()
                    .map(|p| ThresholdObject {
                        ratio: p.ratio,
                        kept: p.kept,
                        correct_kept: p.correct_kept,
                        precision: p.precision(),
                        recall: p.recall(),
                    })
                    .collect(),
            })
            .collect(),
    };
    // Plain data (strings, numbers, options), which always serializes.
    serde_json::to_string_pretty(&document).expect("plain data serializes") + "\n"
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{Value, json};

    #[test]
    fn every_result_with_its_thresholds_and_every_digit() {
        let results = [PairResult {
            param: Some(1.15),
            ..PairResult::sample("OpenCV ORB", "graf 1-2")
        }];
        let text = to_json(&results, 3.0, "cpu; \"quoted\"");
        let doc: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(doc["tolerance_px"], json!(3.0));
        assert_eq!(doc["clatch_settings"], json!("cpu; \"quoted\""));
        let r = &doc["results"][0];
        assert_eq!(r["method"], json!("OpenCV ORB"));
        assert_eq!(r["param"], json!(1.15));
        assert_eq!(
            (r["width_b"].clone(), r["correct_1nn"].clone()),
            (json!(800), json!(28))
        );
        assert_eq!(r["matching_score"], json!(0.3));
        assert_eq!(r["precision"], json!(0.7));
        assert_eq!(
            r["ratio_test"][0],
            json!({"ratio": 0.5, "kept": 5, "correct_kept": 5, "precision": 1.0, "recall": 5.0 / 28.0})
        );
        assert_eq!(r["ratio_test"].as_array().unwrap().len(), 2);
        let none = to_json(&[PairResult::for_test("m", "p", "g", 0, 0)], 3.0, "");
        let doc: Value = serde_json::from_str(&none).unwrap();
        assert_eq!(doc["results"][0]["precision"], Value::Null);
    }
}
