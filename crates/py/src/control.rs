//! Bindings of `autoteach_estimate::control`: transfer functions, frequency-response fitting,
//! margins and the multi-model fixed-structure tuning of 000_3b1454b2b2194811.txt ch. 2.5
//! (issue 31). The friendly wrapper is `python/autoteach/control.py`.

use autoteach_estimate::control::analysis;
use autoteach_estimate::control::baseline::classical_design;
use autoteach_estimate::control::demo::{JointDemo, hand_vibration, run_joint};
use autoteach_estimate::control::fit::{FitOptions, fit_frequency_response};
use autoteach_estimate::control::plant::{
    ArmMasses, Drive, Joint, demo_poses_n, joint_plant, sine_sweep,
};
use autoteach_estimate::control::poly::C64;
use autoteach_estimate::control::sim::lsim;
use autoteach_estimate::control::structure::{ControllerStructure, Section};
use autoteach_estimate::control::tf::TransferFunction;
use autoteach_estimate::control::tune::{TuneReport, TuneSpec, evaluate, tune};
use autoteach_geometry::robot::RobotParams;
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rand::SeedableRng;

use crate::convert::{self, finite_array};
use crate::errors;

type Arr<'py> = Bound<'py, PyArrayDyn<f64>>;

fn vector(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<f64>> {
    finite_array(obj, name)?.vector()
}

fn np<'py>(py: Python<'py>, v: Vec<f64>) -> PyResult<Arr<'py>> {
    let n = v.len();
    convert::to_numpy(py, v, &[n])
}

fn tf(num: &Bound<'_, PyAny>, den: &Bound<'_, PyAny>) -> PyResult<TransferFunction> {
    TransferFunction::new(&vector(num, "num")?, &vector(den, "den")?).map_err(errors::estimate)
}

fn tf_out<'py>(py: Python<'py>, g: &TransferFunction) -> PyResult<(Arr<'py>, Arr<'py>)> {
    Ok((np(py, g.num().to_vec())?, np(py, g.den().to_vec())?))
}

fn complex_out<'py>(py: Python<'py>, z: &[C64]) -> PyResult<(Arr<'py>, Arr<'py>)> {
    Ok((
        np(py, z.iter().map(|c| c.re).collect())?,
        np(py, z.iter().map(|c| c.im).collect())?,
    ))
}

/// Normalised `(num, den)` (trimmed, monic denominator); errors on a zero denominator or NaN.
#[pyfunction]
fn control_tf_normalize<'py>(
    py: Python<'py>,
    num: &Bound<'py, PyAny>,
    den: &Bound<'py, PyAny>,
) -> PyResult<(Arr<'py>, Arr<'py>)> {
    tf_out(py, &tf(num, den)?)
}

/// Roots of a polynomial (descending coefficients) as `(re, im)`.
#[pyfunction]
fn control_roots<'py>(py: Python<'py>, p: &Bound<'py, PyAny>) -> PyResult<(Arr<'py>, Arr<'py>)> {
    let p = vector(p, "p")?;
    if p.is_empty() {
        return Err(errors::invalid_input("p must not be empty"));
    }
    complex_out(py, &autoteach_estimate::control::poly::roots(&p))
}

/// `G(jω)` as `(re, im)`.
#[pyfunction]
fn control_freq_resp<'py>(
    py: Python<'py>,
    num: &Bound<'py, PyAny>,
    den: &Bound<'py, PyAny>,
    w: &Bound<'py, PyAny>,
) -> PyResult<(Arr<'py>, Arr<'py>)> {
    let g = tf(num, den)?;
    let w = vector(w, "omega")?;
    complex_out(py, &g.freq_resp_many(&w))
}

/// Series connection `G1 G2`.
#[pyfunction]
fn control_series<'py>(
    py: Python<'py>,
    n1: &Bound<'py, PyAny>,
    d1: &Bound<'py, PyAny>,
    n2: &Bound<'py, PyAny>,
    d2: &Bound<'py, PyAny>,
) -> PyResult<(Arr<'py>, Arr<'py>)> {
    tf_out(py, &tf(n1, d1)?.series(&tf(n2, d2)?))
}

/// Parallel connection `G1 + G2`.
#[pyfunction]
fn control_parallel<'py>(
    py: Python<'py>,
    n1: &Bound<'py, PyAny>,
    d1: &Bound<'py, PyAny>,
    n2: &Bound<'py, PyAny>,
    d2: &Bound<'py, PyAny>,
) -> PyResult<(Arr<'py>, Arr<'py>)> {
    tf_out(py, &tf(n1, d1)?.parallel(&tf(n2, d2)?))
}

/// Negative feedback `G1 / (1 + G1 G2)`.
#[pyfunction]
fn control_feedback<'py>(
    py: Python<'py>,
    n1: &Bound<'py, PyAny>,
    d1: &Bound<'py, PyAny>,
    n2: &Bound<'py, PyAny>,
    d2: &Bound<'py, PyAny>,
) -> PyResult<(Arr<'py>, Arr<'py>)> {
    let g = tf(n1, d1)?
        .feedback(&tf(n2, d2)?)
        .map_err(errors::estimate)?;
    tf_out(py, &g)
}

/// `(gain margin, phase margin °, phase-crossover ω, gain-crossover ω)` of a loop.
#[pyfunction]
fn control_margins(
    num: &Bound<'_, PyAny>,
    den: &Bound<'_, PyAny>,
) -> PyResult<(f64, f64, f64, f64)> {
    let m = analysis::margins(&tf(num, den)?);
    Ok((
        m.gain_margin,
        m.phase_margin_deg,
        m.w_phase_crossover,
        m.w_gain_crossover,
    ))
}

/// First frequency where the gain drops `dbdrop` dB below DC.
#[pyfunction]
#[pyo3(signature = (num, den, dbdrop=-3.0))]
fn control_bandwidth(num: &Bound<'_, PyAny>, den: &Bound<'_, PyAny>, dbdrop: f64) -> PyResult<f64> {
    if !(dbdrop.is_finite() && dbdrop < 0.0) {
        return Err(errors::invalid_input(format!(
            "dbdrop must be a negative number of dB, got {dbdrop}"
        )));
    }
    Ok(analysis::bandwidth(&tf(num, den)?, dbdrop))
}

/// `(peak |S|, ω)` of the sensitivity of a loop.
#[pyfunction]
fn control_sensitivity_peak(
    num: &Bound<'_, PyAny>,
    den: &Bound<'_, PyAny>,
) -> PyResult<(f64, f64)> {
    Ok(analysis::sensitivity_peak(&tf(num, den)?))
}

/// Smallest damping of the closed-loop poles of a loop.
#[pyfunction]
fn control_closed_loop_damping(num: &Bound<'_, PyAny>, den: &Bound<'_, PyAny>) -> PyResult<f64> {
    Ok(analysis::closed_loop_damping(&tf(num, den)?))
}

/// ZOH simulation of `G` driven by `u` sampled at `dt`.
#[pyfunction]
fn control_lsim<'py>(
    py: Python<'py>,
    num: &Bound<'py, PyAny>,
    den: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    dt: f64,
) -> PyResult<Arr<'py>> {
    let g = tf(num, den)?;
    let u = vector(u, "u")?;
    let y = convert::detached(py, move || lsim(&g, &u, dt).map_err(errors::estimate))?;
    np(py, y)
}

/// Transfer-function fit; returns `(num, den, residual, reflected poles)`.
#[pyfunction]
#[pyo3(signature = (omega, h_re, h_im, num_order, den_order, *, integrators=0, weights=None, enforce_stable=true))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn control_fit<'py>(
    py: Python<'py>,
    omega: &Bound<'py, PyAny>,
    h_re: &Bound<'py, PyAny>,
    h_im: &Bound<'py, PyAny>,
    num_order: usize,
    den_order: usize,
    integrators: usize,
    weights: Option<&Bound<'py, PyAny>>,
    enforce_stable: bool,
) -> PyResult<(Arr<'py>, Arr<'py>, f64, usize)> {
    // NaN frequencies are reported by the core with their index.
    let w: Vec<f64> = convert::Array::new(omega, "omega")?.vector()?;
    let re = convert::Array::new(h_re, "h")?.vector()?;
    let im = convert::Array::new(h_im, "h")?.vector()?;
    if re.len() != im.len() {
        return Err(errors::invalid_input(
            "h real and imaginary parts differ in length",
        ));
    }
    let h: Vec<C64> = re.iter().zip(&im).map(|(&a, &b)| C64::new(a, b)).collect();
    let weights = match weights {
        Some(o) => Some(convert::Array::new(o, "weights")?.vector()?),
        None => None,
    };
    let opts = FitOptions {
        num_order,
        den_order,
        integrators,
        weights,
        enforce_stable,
        ..Default::default()
    };
    let r = convert::detached(py, move || {
        fit_frequency_response(&w, &h, &opts).map_err(errors::estimate)
    })?;
    let (n, d) = tf_out(py, &r.model)?;
    Ok((n, d, r.residual, r.reflected_poles))
}

fn joint_arg(name: &str) -> PyResult<Joint> {
    match name.to_ascii_uppercase().as_str() {
        "JT2" => Ok(Joint::Jt2),
        "JT4" => Ok(Joint::Jt4),
        _ => Err(errors::invalid_input(format!(
            "joint must be 'JT2' or 'JT4', got {name:?}"
        ))),
    }
}

fn plant_dict<'py>(
    py: Python<'py>,
    p: &autoteach_estimate::control::plant::JointPlant,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("motor", tf_out(py, &p.motor)?)?;
    d.set_item("link", tf_out(py, &p.link)?)?;
    d.set_item("link_inertia", p.link_inertia)?;
    d.set_item("pose", np(py, p.pose.iter().copied().collect())?)?;
    Ok(d)
}

/// The simulated plants of a joint at `count` sweep poses (documented masses and drive).
#[pyfunction]
#[pyo3(signature = (joint, count=6))]
fn control_joint_plants<'py>(
    py: Python<'py>,
    joint: &str,
    count: usize,
) -> PyResult<Bound<'py, PyList>> {
    if count < 2 {
        return Err(errors::invalid_input(format!(
            "count must be at least 2, got {count}"
        )));
    }
    let j = joint_arg(joint)?;
    let params = RobotParams::default();
    let masses = ArmMasses::default();
    let drive = Drive::default_for(j);
    let out = PyList::empty(py);
    for q in demo_poses_n(j, count) {
        let p = joint_plant(&params, &masses, &drive, &q, j).map_err(errors::estimate)?;
        out.append(plant_dict(py, &p)?)?;
    }
    Ok(out)
}

/// Noisy stepped-sine sweep of `G` at `omega`: `(re, im)`.
#[pyfunction]
#[pyo3(signature = (num, den, omega, noise, seed=0))]
fn control_sine_sweep<'py>(
    py: Python<'py>,
    num: &Bound<'py, PyAny>,
    den: &Bound<'py, PyAny>,
    omega: &Bound<'py, PyAny>,
    noise: f64,
    seed: u64,
) -> PyResult<(Arr<'py>, Arr<'py>)> {
    let g = tf(num, den)?;
    let w = vector(omega, "omega")?;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let h = sine_sweep(&g, &w, noise, &mut rng).map_err(errors::estimate)?;
    complex_out(py, &h)
}

fn sections_arg(names: &[String]) -> PyResult<ControllerStructure> {
    let mut out = Vec::new();
    for n in names {
        out.push(match n.as_str() {
            "notch" => Section::Notch,
            "lowpass" => Section::LowPass,
            _ => {
                return Err(errors::invalid_input(format!(
                    "filter sections are 'notch' or 'lowpass', got {n:?}"
                )));
            }
        });
    }
    Ok(ControllerStructure::new(out))
}

fn section_names(st: &ControllerStructure) -> Vec<&'static str> {
    st.sections
        .iter()
        .map(|s| {
            if *s == Section::Notch {
                "notch"
            } else {
                "lowpass"
            }
        })
        .collect()
}

fn get_f(d: &Bound<'_, PyDict>, key: &str) -> PyResult<f64> {
    d.get_item(key)?
        .ok_or_else(|| errors::invalid_input(format!("spec is missing {key:?}")))?
        .extract::<f64>()
        .map_err(|_| errors::invalid_input(format!("spec[{key:?}] must be a number")))
}

fn spec_arg(d: &Bound<'_, PyDict>) -> PyResult<TuneSpec> {
    let grid = d
        .get_item("grid")?
        .ok_or_else(|| errors::invalid_input("spec is missing \"grid\""))?;
    let grid = convert::Array::new(&grid, "spec['grid']")?.vector()?;
    let pair = |k: &str| -> PyResult<(f64, f64)> {
        d.get_item(k)?
            .ok_or_else(|| errors::invalid_input(format!("spec is missing {k:?}")))?
            .extract::<(f64, f64)>()
            .map_err(|_| errors::invalid_input(format!("spec[{k:?}] must be a pair of numbers")))
    };
    let target = d
        .get_item("target")?
        .ok_or_else(|| errors::invalid_input("spec is missing \"target\""))?
        .extract::<(f64, f64, f64)>()
        .map_err(|_| errors::invalid_input("spec['target'] must be (wc, w1, w2)"))?;
    Ok(TuneSpec {
        grid,
        sd_bandwidth: get_f(d, "sd_bandwidth")?,
        sd_peak: get_f(d, "sd_peak")?,
        sd_low: get_f(d, "sd_low")?,
        min_gain_margin_db: get_f(d, "min_gain_margin_db")?,
        min_phase_margin_deg: get_f(d, "min_phase_margin_deg")?,
        min_damping: get_f(d, "min_damping")?,
        damping_max_freq: get_f(d, "damping_max_freq")?,
        max_loop_gain: get_f(d, "max_loop_gain")?,
        gain_band: pair("gain_band")?,
        rolloff_freq: get_f(d, "rolloff_freq")?,
        target,
        max_iterations: get_f(d, "max_iterations")? as usize,
    })
}

fn spec_dict<'py>(py: Python<'py>, s: &TuneSpec) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("grid", np(py, s.grid.clone())?)?;
    d.set_item("sd_bandwidth", s.sd_bandwidth)?;
    d.set_item("sd_peak", s.sd_peak)?;
    d.set_item("sd_low", s.sd_low)?;
    d.set_item("min_gain_margin_db", s.min_gain_margin_db)?;
    d.set_item("min_phase_margin_deg", s.min_phase_margin_deg)?;
    d.set_item("min_damping", s.min_damping)?;
    d.set_item("damping_max_freq", s.damping_max_freq)?;
    d.set_item("max_loop_gain", s.max_loop_gain)?;
    d.set_item("gain_band", s.gain_band)?;
    d.set_item("rolloff_freq", s.rolloff_freq)?;
    d.set_item("target", s.target)?;
    d.set_item("max_iterations", s.max_iterations as f64)?;
    Ok(d)
}

fn report_dict<'py>(
    py: Python<'py>,
    st: &ControllerStructure,
    r: &TuneReport,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("sections", section_names(st))?;
    d.set_item("theta", np(py, r.theta.clone())?)?;
    d.set_item("controller", tf_out(py, &r.controller)?)?;
    d.set_item("success", r.success)?;
    d.set_item("unmet", r.unmet.clone())?;
    d.set_item("objective", r.objective)?;
    d.set_item("iterations", r.iterations)?;
    let plants = PyList::empty(py);
    for p in &r.plants {
        let e = PyDict::new(py);
        e.set_item("gain_margin_db", p.gain_margin_db)?;
        e.set_item("phase_margin_deg", p.phase_margin_deg)?;
        e.set_item("worst_gain_margin_db", p.worst_gain_margin_db)?;
        e.set_item("worst_phase_margin_deg", p.worst_phase_margin_deg)?;
        e.set_item("crossover", p.crossover)?;
        e.set_item("bandwidth", p.bandwidth)?;
        e.set_item("sensitivity_peak", p.sensitivity_peak)?;
        e.set_item("weighted_peak", p.weighted_peak)?;
        e.set_item("damping", p.damping)?;
        e.set_item("damping_all", p.damping_all)?;
        e.set_item("band_gain_ratio", p.band_gain_ratio)?;
        e.set_item("rolloff_ratio", p.rolloff_ratio)?;
        plants.append(e)?;
    }
    d.set_item("plants", plants)?;
    Ok(d)
}

fn plants_arg(plants: &Bound<'_, PyList>) -> PyResult<Vec<TransferFunction>> {
    let mut out = Vec::new();
    for item in plants.iter() {
        let (n, d): (Bound<'_, PyAny>, Bound<'_, PyAny>) = item
            .extract()
            .map_err(|_| errors::invalid_input("each plant must be a (num, den) pair"))?;
        out.push(tf(&n, &d)?);
    }
    Ok(out)
}

/// Multi-model fixed-structure tuning (eq. 2.19): returns the report dict.
#[pyfunction]
#[pyo3(signature = (plants, sections, spec, theta0=None))]
fn control_tune<'py>(
    py: Python<'py>,
    plants: &Bound<'py, PyList>,
    sections: Vec<String>,
    spec: &Bound<'py, PyDict>,
    theta0: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let ps = plants_arg(plants)?;
    let st = sections_arg(&sections)?;
    let sp = spec_arg(spec)?;
    let t0 = match theta0 {
        Some(t) => Some(vector(t, "theta0")?),
        None => None,
    };
    let st2 = st.clone();
    let r = convert::detached(py, move || {
        tune(&ps, &st2, &sp, t0.as_deref()).map_err(errors::estimate)
    })?;
    report_dict(py, &st, &r)
}

/// Evaluates a controller against a spec on a plant set.
#[pyfunction]
fn control_evaluate<'py>(
    py: Python<'py>,
    plants: &Bound<'py, PyList>,
    sections: Vec<String>,
    theta: &Bound<'py, PyAny>,
    spec: &Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyDict>> {
    let ps = plants_arg(plants)?;
    let st = sections_arg(&sections)?;
    let sp = spec_arg(spec)?;
    let th = vector(theta, "theta")?;
    let st2 = st.clone();
    let r = convert::detached(py, move || {
        evaluate(&ps, &st2, &th, &sp).map_err(errors::estimate)
    })?;
    report_dict(py, &st, &r)
}

/// The classical baseline (second-order low-pass + PID, rigid-body rule, detuned to the spec).
#[pyfunction]
fn control_baseline<'py>(
    py: Python<'py>,
    plants: &Bound<'py, PyList>,
    spec: &Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyDict>> {
    let ps = plants_arg(plants)?;
    let sp = spec_arg(spec)?;
    let (st, r) = convert::detached(py, move || {
        classical_design(&ps, &sp).map_err(errors::estimate)
    })?;
    report_dict(py, &st, &r)
}

fn joint_dict<'py>(py: Python<'py>, j: &JointDemo) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let plants = PyList::empty(py);
    for p in &j.plants {
        plants.append(plant_dict(py, p)?)?;
    }
    d.set_item("plants", plants)?;
    d.set_item("sweep_omega", np(py, j.sweep_w.clone())?)?;
    let sweeps = PyList::empty(py);
    for s in &j.sweeps {
        sweeps.append(complex_out(py, s)?)?;
    }
    d.set_item("sweeps", sweeps)?;
    let fits = PyList::empty(py);
    for f in &j.fits {
        let e = PyDict::new(py);
        e.set_item("model", tf_out(py, &f.model)?)?;
        e.set_item("residual", f.residual)?;
        fits.append(e)?;
    }
    d.set_item("fits", fits)?;
    d.set_item("spec", spec_dict(py, &j.spec)?)?;
    d.set_item("baseline", report_dict(py, &j.baseline.0, &j.baseline.1)?)?;
    d.set_item("tuned", report_dict(py, &j.tuned.0, &j.tuned.1)?)?;
    d.set_item(
        "tuned_on_fits",
        report_dict(py, &j.tuned.0, &j.tuned_on_fits)?,
    )?;
    Ok(d)
}

/// The whole simulated experiment (Tables 2.3–2.4): JT2 and JT4 plants, sweeps with relative
/// `noise`, fits, baseline, tuned controllers with `sections`, and the hand vibration.
#[pyfunction]
#[pyo3(signature = (noise=0.01, seed=0, sections=None, move_jt2=1.0, move_jt4=-1.5, duration=0.8, settle=0.4))]
#[allow(clippy::too_many_arguments)]
fn control_demo<'py>(
    py: Python<'py>,
    noise: f64,
    seed: u64,
    sections: Option<Vec<String>>,
    move_jt2: f64,
    move_jt4: f64,
    duration: f64,
    settle: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let st = match sections {
        Some(s) => sections_arg(&s)?,
        None => ControllerStructure::new(vec![Section::Notch, Section::LowPass]),
    };
    let (j2, j4, vb, vt) = convert::detached(py, move || {
        let run = || -> autoteach_estimate::Result<_> {
            let j2 = run_joint(Joint::Jt2, noise, seed, st.sections.clone())?;
            let j4 = run_joint(Joint::Jt4, noise, seed.wrapping_add(1), st.sections.clone())?;
            let vb = hand_vibration(&j2, &j4, 0, move_jt2, move_jt4, duration, settle)?;
            let vt = hand_vibration(&j2, &j4, 1, move_jt2, move_jt4, duration, settle)?;
            Ok((j2, j4, vb, vt))
        };
        run().map_err(errors::estimate)
    })?;
    let d = PyDict::new(py);
    d.set_item("JT2", joint_dict(py, &j2)?)?;
    d.set_item("JT4", joint_dict(py, &j4)?)?;
    let v = PyDict::new(py);
    for (name, x) in [("baseline", vb), ("tuned", vt)] {
        let e = PyDict::new(py);
        e.set_item("total", x.total.to_vec())?;
        e.set_item("vibration", x.vibration.to_vec())?;
        v.set_item(name, e)?;
    }
    d.set_item("vibration", v)?;
    Ok(d)
}

/// Adds the control functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(control_tf_normalize, m)?)?;
    m.add_function(wrap_pyfunction!(control_roots, m)?)?;
    m.add_function(wrap_pyfunction!(control_freq_resp, m)?)?;
    m.add_function(wrap_pyfunction!(control_series, m)?)?;
    m.add_function(wrap_pyfunction!(control_parallel, m)?)?;
    m.add_function(wrap_pyfunction!(control_feedback, m)?)?;
    m.add_function(wrap_pyfunction!(control_margins, m)?)?;
    m.add_function(wrap_pyfunction!(control_bandwidth, m)?)?;
    m.add_function(wrap_pyfunction!(control_sensitivity_peak, m)?)?;
    m.add_function(wrap_pyfunction!(control_closed_loop_damping, m)?)?;
    m.add_function(wrap_pyfunction!(control_lsim, m)?)?;
    m.add_function(wrap_pyfunction!(control_fit, m)?)?;
    m.add_function(wrap_pyfunction!(control_joint_plants, m)?)?;
    m.add_function(wrap_pyfunction!(control_sine_sweep, m)?)?;
    m.add_function(wrap_pyfunction!(control_tune, m)?)?;
    m.add_function(wrap_pyfunction!(control_evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(control_baseline, m)?)?;
    m.add_function(wrap_pyfunction!(control_demo, m)?)?;
    Ok(())
}
