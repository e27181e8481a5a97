use tribo_explain::*;
use tribo_physics::integrate::Method;
use tribo_physics::law::FrictionLaw;
use tribo_physics::model::{Model, Rig};
use tribo_physics::sensor::{generate, RecordSpec, SensorModel, Thermal};
#[test]
fn dbg() {
    let sp = RecordSpec { rig: Rig::REAL, x0_m: 667e-6, v0_m_s: 0.0, duration_s: 1.3, rate_hz: 10_000.0 };
    let m = Model::new(FrictionLaw::coulomb_viscous(0.02, 0.002));
    for th in [None, Some(Thermal{start_c: 40.0, drift_c_per_s: 8.0, noise_c: 0.1})] {
        let s = SensorModel { seed: 72, thermal: th, ..SensorModel::default() };
        let rec = generate(&sp, &m, Method::dopri(1e-10), Some(&s)).unwrap();
        let data = Prepared::new(&rec, 400, 3000, Some(300.0)).unwrap();
        let e = evaluate(&data, &Spec::base(vec![0,1]), &[0.02, 0.002]).unwrap();
        eprintln!("th {:?} gap {} {} {:?} temp {:?}", th.is_some(), e.gap, e.gap_envelope, e.gap_force, data.temp);
        let fm = data.f_meas.as_ref().unwrap();
        let sim = model::simulate_spec(&data, &Spec::base(vec![0,1]), &[0.02, 0.002]).unwrap();
        let mut big: Vec<(f64, usize)> = (0..fm.len()).map(|i| ((sim.f_meas[i]-fm[i]).abs(), i)).collect();
        big.sort_by(|a,b| b.0.total_cmp(&a.0));
        eprintln!("  biggest {:?}", &big[..5]);
    }
}
