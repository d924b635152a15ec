//! Ray sets as the runner makes them: a spec (kind and parameters) → rays, generated from
//! what they need — ao and diffuse start at the primary rays' f32 hits, grazing rays aim at
//! the binary BVH's boxes — or read from a `.npy` file and checked.

use crate::base::{Hit, Ray};
use crate::bvh::BinaryBvh;
use crate::layout::{Encoded, LayoutId};
use crate::rays::{self, Camera, RayKind, RayParams};
use crate::scene::Scene;

/// A ray set: its kind and the parameters of generated kinds.
#[derive(Clone, Debug, PartialEq)]
pub struct RaySpec {
    pub kind: RayKind,
    pub params: RayParams,
}

/// Rays and, once something needs them, the f32 reference's hits for them (layout f32, B = 4,
/// single rays: [`super::Runner::f32_hits`]).
pub struct RaySet {
    pub spec: RaySpec,
    pub rays: Vec<Ray>,
    pub f32_hits: Option<Vec<Hit>>,
}

/// A ray set of one scene: that scene's load (`epoch`) and the set's index there. A ray set of
/// another scene is refused, not read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RaySetId {
    pub(super) epoch: u64,
    pub(super) index: usize,
}

/// The rays of `spec` on `scene`. Ao and diffuse rays start at `primary`: the primary rays of
/// the same parameters and their f32 hits.
pub fn generate(
    scene: &Scene,
    bin: &BinaryBvh,
    spec: &RaySpec,
    primary: Option<(&[Ray], &[Hit])>,
) -> anyhow::Result<Vec<Ray>> {
    let p = &spec.params;
    Ok(match &spec.kind {
        RayKind::Primary => {
            rays::primary(&p.camera.unwrap_or_else(|| Camera::framing(&scene.bounds)), p.width, p.height)?
        }
        RayKind::Ao | RayKind::Diffuse => {
            let (prim, hits) =
                primary.ok_or_else(|| anyhow::anyhow!("{} rays start at the primary hits", spec.kind))?;
            let len = (spec.kind == RayKind::Ao).then_some(rays::AO_LENGTH);
            rays::secondary(scene, prim, hits, p.seed, len)
        }
        RayKind::Grazing => {
            let boxes: Vec<_> = bin.nodes.iter().map(|n| n.bounds).collect();
            rays::grazing(scene, &boxes, p.grazing, p.seed)
        }
        RayKind::File(path) => {
            let r = crate::npy::read_rays(path)?;
            crate::base::validate(&r, &path.display().to_string())?;
            r
        }
    })
}

/// The rays of `spec` on `scene` without a runner (tests, benchmarks): the primary rays of
/// ao and diffuse are traced by the f32 reference here.
pub fn make(scene: &Scene, bin: &BinaryBvh, spec: &RaySpec) -> anyhow::Result<Vec<Ray>> {
    match spec.kind {
        RayKind::Ao | RayKind::Diffuse => {
            let prim = generate(scene, bin, &RaySpec { kind: RayKind::Primary, params: spec.params.clone() }, None)?;
            let mut hits = Encoded::new(scene, bin, LayoutId::f32(), 4)?.trace_raw_default(&prim);
            bin.resolve(scene, &prim, &mut hits);
            generate(scene, bin, spec, Some((&prim, &hits)))
        }
        _ => generate(scene, bin, spec, None),
    }
}

impl RaySpec {
    /// A spec of `kind` with these parameters.
    pub fn new(kind: RayKind, params: RayParams) -> RaySpec {
        RaySpec { kind, params }
    }
}
