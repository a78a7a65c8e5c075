//! The model store's view of learning: the model kinds of `POST /api/v1/models`,
//! their parameters as the REST body gives them, one [`train`] entry point for the
//! service's training jobs, and [`AnyModel`], the serialisable trained model the
//! monitors predict with.

use std::time::Instant;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::cv::CvParams;
use super::local::{LwLsSvmModel, LwLsSvmParams};
use super::lssvm::{LsSvmModel, LsSvmParams};
use super::svm::{self, OcSvmModel, OcSvmParams, SvcModel, SvcParams};
use super::{Dataset, Fitted, LearnError, Progress, TrainingMetrics};

/// Deserialises `value` as `T`; on failure returns the dotted path of the failing
/// value as serde_path_to_error tracked it (`""` at the top, `folds`, `x[2]`) and
/// serde's reason. Used for `params` here and for `cv` by the service.
pub fn parse_at<T: serde::de::DeserializeOwned>(value: &Value) -> Result<T, (String, String)> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        let path = if path == "." { String::new() } else { path };
        (path, e.into_inner().to_string())
    })
}

/// Version of the stored model format; bumped when a model struct changes shape.
pub const FORMAT_VERSION: u32 = 1;

/// The model kinds (docs/architecture.md §A5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ModelKind {
    /// Batch LS-SVM regression (seed 000 eq. 6).
    #[serde(rename = "lssvm")]
    LsSvm,
    /// Locally weighted LS-SVM regression (seed 000 §1.2).
    #[serde(rename = "lw-lssvm")]
    LwLsSvm,
    /// C-SVC classifier by SMO (seed 002).
    #[serde(rename = "svm")]
    Svm,
    /// One-class SVM / SVDD by SMO (seed 003).
    #[serde(rename = "ocsvm")]
    OcSvm,
}

impl ModelKind {
    /// The wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            ModelKind::LsSvm => "lssvm",
            ModelKind::LwLsSvm => "lw-lssvm",
            ModelKind::Svm => "svm",
            ModelKind::OcSvm => "ocsvm",
        }
    }

    /// True for the regression kinds (they need `y` and predict `y`).
    pub fn is_regression(self) -> bool {
        matches!(self, ModelKind::LsSvm | ModelKind::LwLsSvm)
    }

    /// True when training needs targets or labels `y` (all but `ocsvm`).
    pub fn needs_y(self) -> bool {
        !matches!(self, ModelKind::OcSvm)
    }
}

/// Parameters of one model kind, as `params` of `POST /api/v1/models`.
#[derive(Debug, Clone, PartialEq)]
pub enum ModelParams {
    /// `lssvm`.
    LsSvm(LsSvmParams),
    /// `lw-lssvm`.
    LwLsSvm(LwLsSvmParams),
    /// `svm`.
    Svm(SvcParams),
    /// `ocsvm`.
    OcSvm(OcSvmParams),
}

impl ModelParams {
    /// Parses `params` for `kind` (missing fields take their documented defaults,
    /// unknown fields are refused) and checks them. A parse error names the exact
    /// path inside `params` (serde_path_to_error), e.g. `sigma2` or `gama`.
    pub fn from_json(kind: ModelKind, params: &Value) -> Result<Self, LearnError> {
        let params = if params.is_null() {
            &Value::Object(Default::default())
        } else {
            params
        };
        let name = if kind.is_regression() {
            "reg"
        } else {
            "kernel_gamma"
        };
        if params.get(name).is_some() && params.get("gamma").is_some() {
            return Err(LearnError::params(
                "gamma",
                format!("`gamma` is the old spelling of `{name}` for this kind: give one of them"),
            ));
        }
        let parsed = match kind {
            ModelKind::LsSvm => ModelParams::LsSvm(parse(params)?),
            ModelKind::LwLsSvm => ModelParams::LwLsSvm(parse(params)?),
            ModelKind::Svm => ModelParams::Svm(parse(params)?),
            ModelKind::OcSvm => ModelParams::OcSvm(parse(params)?),
        };
        // A range error names the spelling the body used.
        parsed.check().map_err(|e| match e {
            LearnError::InvalidParams { field, reason }
                if field == name && params.get(name).is_none() && params.get("gamma").is_some() =>
            {
                LearnError::params("gamma", reason)
            }
            other => other,
        })?;
        Ok(parsed)
    }

    /// The kind these parameters belong to.
    pub fn kind(&self) -> ModelKind {
        match self {
            ModelParams::LsSvm(_) => ModelKind::LsSvm,
            ModelParams::LwLsSvm(_) => ModelKind::LwLsSvm,
            ModelParams::Svm(_) => ModelKind::Svm,
            ModelParams::OcSvm(_) => ModelKind::OcSvm,
        }
    }

    /// Validates every parameter; the error names the field.
    pub fn check(&self) -> Result<(), LearnError> {
        match self {
            ModelParams::LsSvm(p) => p.check().map(drop),
            ModelParams::LwLsSvm(p) => p.check().map(drop),
            ModelParams::Svm(p) => p.check().map(drop),
            ModelParams::OcSvm(p) => p.check().map(drop),
        }
    }

    /// True when training runs cross-validation first: a regression kind with a
    /// hyper-parameter `"auto"` that its kernel uses, or with a `cv` block. Read from
    /// the typed parameters, never from their JSON.
    pub fn tunes(&self, cv_given: bool) -> bool {
        match self {
            ModelParams::LsSvm(p) => p.check().is_ok_and(|v| v.tunes(cv_given)),
            ModelParams::LwLsSvm(p) => p.check().is_ok_and(|v| v.tunes(cv_given)),
            ModelParams::Svm(_) | ModelParams::OcSvm(_) => false,
        }
    }

    /// The parameters as JSON, defaults filled in (what the model record shows).
    pub fn to_json(&self) -> Value {
        let v = match self {
            ModelParams::LsSvm(p) => serde_json::to_value(p),
            ModelParams::LwLsSvm(p) => serde_json::to_value(p),
            ModelParams::Svm(p) => serde_json::to_value(p),
            ModelParams::OcSvm(p) => serde_json::to_value(p),
        };
        v.unwrap_or(Value::Null)
    }
}

/// Deserialises one kind's params; the error's field is the path serde_path_to_error
/// tracked to the failing value (empty for `params` itself).
fn parse<T: serde::de::DeserializeOwned>(params: &Value) -> Result<T, LearnError> {
    parse_at(params).map_err(|(field, reason)| LearnError::params(field, reason))
}

/// A trained model, the parameters it was trained with (hyper-parameters chosen by
/// CV filled in), and what training measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Trained {
    /// The model.
    pub model: AnyModel,
    /// Effective parameters.
    pub params: ModelParams,
    /// Training figures.
    pub metrics: TrainingMetrics,
}

impl Trained {
    /// One algorithm's [`Fitted`] result, wrapped: the only place an algorithm's own
    /// model becomes an [`AnyModel`].
    fn from<M, P>(
        fitted: Fitted<M, P>,
        model: impl FnOnce(M) -> AnyModel,
        params: impl FnOnce(P) -> ModelParams,
    ) -> Self {
        Trained {
            model: model(fitted.model),
            params: params(fitted.params),
            metrics: fitted.metrics,
        }
    }
}

/// Trains a model of `params.kind()` on `data`, running cross-validation first when
/// `cv` is given or a hyper-parameter is `"auto"`. Blocking and CPU-heavy: the
/// service calls it on the blocking pool.
pub fn train(
    params: &ModelParams,
    cv: Option<&CvParams>,
    data: &Dataset,
    progress: &dyn Progress,
) -> Result<Trained, LearnError> {
    if let Some(cv) = cv {
        cv.check()?;
    }
    if params.kind().needs_y() {
        data.require_y()?;
    }
    let started = Instant::now();
    let mut trained = match params {
        ModelParams::LsSvm(p) => Trained::from(
            p.check()?.fit_with(cv, data, progress)?,
            AnyModel::LsSvm,
            ModelParams::LsSvm,
        ),
        ModelParams::LwLsSvm(p) => Trained::from(
            p.check()?.fit_with(cv, data, progress)?,
            AnyModel::LwLsSvm,
            ModelParams::LwLsSvm,
        ),
        ModelParams::Svm(p) => {
            let valid = p.check()?;
            svm::refuse_cv(cv)?;
            Trained::from(
                valid.fit_with(data, progress)?,
                AnyModel::Svm,
                ModelParams::Svm,
            )
        }
        ModelParams::OcSvm(p) => {
            let valid = p.check()?;
            svm::refuse_cv(cv)?;
            Trained::from(
                valid.fit_with(data, progress)?,
                AnyModel::OcSvm,
                ModelParams::OcSvm,
            )
        }
    };
    trained.metrics.n = data.n();
    trained.metrics.dim = data.dim();
    trained.metrics.seconds = started.elapsed().as_secs_f64();
    progress.report(1.0, "done");
    Ok(trained)
}

/// A trained model of any kind.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind")]
pub enum AnyModel {
    /// `lssvm`.
    #[serde(rename = "lssvm")]
    LsSvm(LsSvmModel),
    /// `lw-lssvm`.
    #[serde(rename = "lw-lssvm")]
    LwLsSvm(LwLsSvmModel),
    /// `svm`.
    #[serde(rename = "svm")]
    Svm(SvcModel),
    /// `ocsvm`.
    #[serde(rename = "ocsvm")]
    OcSvm(OcSvmModel),
}

/// The stored envelope: format version and model.
#[derive(Serialize, Deserialize)]
struct Stored {
    format_version: u32,
    model: AnyModel,
}

/// Predictions for a set of inputs (`POST /api/v1/models/{id}/predict`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Prediction {
    /// Regression kinds.
    Regression {
        /// Predicted values, original units.
        y: Vec<f64>,
    },
    /// Classifiers: decision values and labels. `svm`: label +1 when the decision
    /// is ≥ 0 (the positive class, "fault" in seed 002), else −1. `ocsvm`: positive
    /// decision = inside the boundary, label +1 (normal), else −1 (anomaly), as
    /// scikit-learn's `OneClassSVM`.
    Classification {
        /// Decision values.
        decision: Vec<f64>,
        /// Labels, +1 or −1.
        label: Vec<i32>,
    },
}

impl AnyModel {
    /// The kind.
    pub fn kind(&self) -> ModelKind {
        match self {
            AnyModel::LsSvm(_) => ModelKind::LsSvm,
            AnyModel::LwLsSvm(_) => ModelKind::LwLsSvm,
            AnyModel::Svm(_) => ModelKind::Svm,
            AnyModel::OcSvm(_) => ModelKind::OcSvm,
        }
    }

    /// The input dimension the model was trained on.
    pub fn input_dim(&self) -> usize {
        match self {
            AnyModel::LsSvm(m) => m.input_dim(),
            AnyModel::LwLsSvm(m) => m.input_dim(),
            AnyModel::Svm(m) => m.input_dim(),
            AnyModel::OcSvm(m) => m.input_dim(),
        }
    }

    /// One regression value (regression kinds) or decision value (classifiers) for
    /// one input of [`AnyModel::input_dim`] values. The monitors' hot path.
    pub fn predict_one(&self, x: &[f64]) -> f64 {
        match self {
            AnyModel::LsSvm(m) => m.predict_one(x),
            AnyModel::LwLsSvm(m) => m.predict_one(x),
            AnyModel::Svm(m) => m.decision_one(x),
            AnyModel::OcSvm(m) => m.decision_one(x),
        }
    }

    /// Predicts every row of `x`; `x`'s dimension must match.
    pub fn predict(&self, x: &Dataset) -> Result<Prediction, LearnError> {
        if x.dim() != self.input_dim() {
            return Err(LearnError::data(
                "x",
                format!(
                    "has {} features, the model was trained on {}",
                    x.dim(),
                    self.input_dim()
                ),
            ));
        }
        let values: Vec<f64> = (0..x.n()).map(|i| self.predict_one(&x.row(i))).collect();
        Ok(if self.kind().is_regression() {
            Prediction::Regression { y: values }
        } else {
            let label = values
                .iter()
                .map(|&d| if d >= 0.0 { 1 } else { -1 })
                .collect();
            Prediction::Classification {
                decision: values,
                label,
            }
        })
    }

    /// The stored form: JSON with a format version.
    pub fn to_stored_json(&self) -> String {
        serde_json::to_string(&Stored {
            format_version: FORMAT_VERSION,
            model: self.clone(),
        })
        .unwrap_or_default()
    }

    /// Reads the stored form, refusing other format versions.
    pub fn from_stored_json(text: &str) -> Result<Self, LearnError> {
        #[derive(Deserialize)]
        struct Version {
            format_version: u32,
        }
        let v: Version = serde_json::from_str(text)
            .map_err(|e| LearnError::data("model", format!("not a stored model: {e}")))?;
        if v.format_version != FORMAT_VERSION {
            return Err(LearnError::data(
                "model",
                format!(
                    "stored with format version {}, this build reads {FORMAT_VERSION}",
                    v.format_version
                ),
            ));
        }
        let s: Stored = serde_json::from_str(text)
            .map_err(|e| LearnError::data("model", format!("not a stored model: {e}")))?;
        Ok(s.model)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(kind: ModelKind, params: Value) -> String {
        let e = ModelParams::from_json(kind, &params).unwrap_err();
        assert!(matches!(e, LearnError::InvalidParams { .. }), "{e:?}");
        e.field().unwrap_or_default().to_owned()
    }

    #[test]
    fn parse_errors_name_the_exact_path_of_the_bad_field() {
        use serde_json::json;
        assert_eq!(field(ModelKind::LsSvm, json!({"gama": 1})), "gama");
        assert_eq!(field(ModelKind::LsSvm, json!({"sigma2": [1]})), "sigma2");
        assert_eq!(field(ModelKind::LsSvm, json!({"kernel": "poly"})), "kernel");
        assert_eq!(field(ModelKind::LwLsSvm, json!({"k": -3})), "k");
        assert_eq!(field(ModelKind::Svm, json!({"C": "big"})), "C");
        assert_eq!(field(ModelKind::Svm, json!({"max_iter": 1.5})), "max_iter");
        assert_eq!(field(ModelKind::OcSvm, json!({"kernel": "rbf"})), "kernel");
        assert_eq!(field(ModelKind::OcSvm, json!("x")), "");
        // A name and its alias together: refused naming the alias.
        assert_eq!(
            field(ModelKind::LsSvm, json!({"reg": 1, "gamma": 1})),
            "gamma"
        );
        assert_eq!(
            field(ModelKind::Svm, json!({"kernel_gamma": 1, "gamma": 1})),
            "gamma"
        );
    }

    #[test]
    fn tuning_is_read_from_the_typed_params() {
        use serde_json::json;
        let p = |kind, v| ModelParams::from_json(kind, &v).unwrap();
        assert!(p(ModelKind::LsSvm, json!({})).tunes(false));
        assert!(p(ModelKind::LsSvm, json!({"reg": 1, "sigma2": "auto"})).tunes(false));
        assert!(!p(ModelKind::LsSvm, json!({"reg": 1, "sigma2": 2})).tunes(false));
        assert!(p(ModelKind::LsSvm, json!({"reg": 1, "sigma2": 2})).tunes(true));
        // The linear kernel has no width: its default sigma2 "auto" is not searched.
        assert!(!p(ModelKind::LsSvm, json!({"gamma": 1, "kernel": "linear"})).tunes(false));
        assert!(p(ModelKind::LwLsSvm, json!({"gamma": "auto", "sigma2": 1})).tunes(false));
        assert!(!p(ModelKind::Svm, json!({})).tunes(false));
    }

    #[test]
    fn kinds_round_trip_their_wire_names() {
        for k in [
            ModelKind::LsSvm,
            ModelKind::LwLsSvm,
            ModelKind::Svm,
            ModelKind::OcSvm,
        ] {
            let v = serde_json::to_value(k).unwrap();
            assert_eq!(v, k.as_str());
            assert_eq!(serde_json::from_value::<ModelKind>(v).unwrap(), k);
        }
    }
}
