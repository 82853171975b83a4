//! A volume's values held in the type they were stored in.
//!
//! A thin-slice CT of 512 x 512 x 532 voxels is 139 MB as its file's 8-bit values and 557 MB
//! as `f32`; a 1024^3 16-bit micro-CT 2 GiB against 4. Every reader of the values (the
//! classification, picking, statistics) takes them as `f32` one at a time or a run at a time,
//! and the hot loops are written once, generic over [`Voxel`], and instantiated per stored type
//! by the crate-internal `dispatch!`.
//!
//! 8- and 16-bit integers are kept as they are; 32-bit integers and 64-bit floats, which `f32`
//! was already the drawing precision of, are held as `f32`, as are values a rescale made
//! fractional.

use rayon::prelude::*;

use super::ScalarType;

/// A type voxel values are held in: exactly convertible to `f32`.
pub trait Voxel: Copy + Send + Sync + bytemuck::Pod + 'static {
    /// The value as `f32` (exact for every implementing type).
    fn to_f32(self) -> f32;
    /// The value of this type nearest `v`: rounded to the nearest integer and held to the
    /// type's range for the integer types (a mean of stored values is within it).
    fn nearest(v: f64) -> Self;
}

macro_rules! voxel {
    ($($t:ty),*) => {$(
        impl Voxel for $t {
            #[inline(always)]
            fn to_f32(self) -> f32 {
                f32::from(self)
            }
            #[inline(always)]
            fn nearest(v: f64) -> Self {
                // `as` saturates at the type's ends.
                v.round() as $t
            }
        }
    )*};
}
voxel!(u8, i8, u16, i16);

impl Voxel for f32 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }
    #[inline(always)]
    fn nearest(v: f64) -> Self {
        v as f32
    }
}

/// One value per voxel, x fastest, in the type the file stored them in (see the
/// [module documentation](self)).
#[derive(Debug, Clone)]
pub enum Voxels {
    /// Unsigned 8-bit values.
    U8(Vec<u8>),
    /// Signed 8-bit values.
    I8(Vec<i8>),
    /// Unsigned 16-bit values.
    U16(Vec<u16>),
    /// Signed 16-bit values (CT in Hounsfield units, as most scanners store it).
    I16(Vec<i16>),
    /// Values of any other type, or rescaled to fractions.
    F32(Vec<f32>),
}

/// Runs `$body` with `$v` bound to the values' slice in their own type, so that a loop over
/// them is compiled once per type instead of matching on the type per value.
macro_rules! dispatch_voxels {
    ($voxels:expr, $v:ident => $body:expr) => {
        match $voxels {
            $crate::volume::Voxels::U8($v) => $body,
            $crate::volume::Voxels::I8($v) => $body,
            $crate::volume::Voxels::U16($v) => $body,
            $crate::volume::Voxels::I16($v) => $body,
            $crate::volume::Voxels::F32($v) => $body,
        }
    };
}
pub(crate) use dispatch_voxels as dispatch;

impl Default for Voxels {
    fn default() -> Self {
        Voxels::F32(Vec::new())
    }
}

impl Voxels {
    /// No values yet, held in the type that keeps `scalar` exactly where there is one (8- and
    /// 16-bit integers), else `f32`.
    pub fn new(scalar: ScalarType) -> Self {
        match scalar {
            ScalarType::U8 => Voxels::U8(Vec::new()),
            ScalarType::I8 => Voxels::I8(Vec::new()),
            ScalarType::U16 => Voxels::U16(Vec::new()),
            ScalarType::I16 => Voxels::I16(Vec::new()),
            ScalarType::U32 | ScalarType::I32 | ScalarType::F32 | ScalarType::F64 => {
                Voxels::F32(Vec::new())
            }
        }
    }

    /// Bytes a value of `scalar` is held in.
    pub fn held_bytes(scalar: ScalarType) -> usize {
        Voxels::new(scalar).scalar_type().size()
    }

    /// The number of values.
    pub fn len(&self) -> usize {
        dispatch!(self, v => v.len())
    }

    /// Whether there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The type the values are held in.
    pub fn scalar_type(&self) -> ScalarType {
        match self {
            Voxels::U8(_) => ScalarType::U8,
            Voxels::I8(_) => ScalarType::I8,
            Voxels::U16(_) => ScalarType::U16,
            Voxels::I16(_) => ScalarType::I16,
            Voxels::F32(_) => ScalarType::F32,
        }
    }

    /// Bytes the values take.
    pub fn bytes(&self) -> usize {
        dispatch!(self, v => std::mem::size_of_val(v.as_slice()))
    }

    /// Value `i` as `f32`, `None` past the end.
    #[inline]
    pub fn get(&self, i: usize) -> Option<f32> {
        dispatch!(self, v => v.get(i).map(|x| x.to_f32()))
    }

    /// Value `i` as `f32`.
    ///
    /// # Panics
    /// When `i` is past the end, as slice indexing does.
    #[inline]
    pub fn at(&self, i: usize) -> f32 {
        dispatch!(self, v => v[i].to_f32())
    }

    /// The values from `start` on as `f32`, as many as `out` holds.
    ///
    /// # Panics
    /// When they run past the end, as slice indexing does.
    pub fn read(&self, start: usize, out: &mut [f32]) {
        dispatch!(self, v => {
            let n = out.len();
            for (o, x) in out.iter_mut().zip(&v[start..start + n]) {
                *o = x.to_f32();
            }
        })
    }

    /// Every value, in order, as `f32`.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = f32> + '_ {
        (0..self.len()).map(|i| self.at(i))
    }

    /// The values as `f32`: a copy of all of them, for tests and small volumes.
    pub fn to_f32_vec(&self) -> Vec<f32> {
        dispatch!(self, v => v.iter().map(|x| x.to_f32()).collect())
    }

    /// `f` of each run of `chunk` values (the last one shorter) as `f32`, on every core, in
    /// order. A run of another type is converted into a buffer of its own, never the whole.
    pub fn par_chunks<R: Send>(&self, chunk: usize, f: impl Fn(&[f32]) -> R + Sync) -> Vec<R> {
        let chunk = chunk.max(1);
        if let Voxels::F32(v) = self {
            return v.par_chunks(chunk).map(&f).collect();
        }
        (0..self.len().div_ceil(chunk))
            .into_par_iter()
            .map(|c| {
                let start = c * chunk;
                let mut buffer = vec![0.0f32; chunk.min(self.len() - start)];
                self.read(start, &mut buffer);
                f(&buffer)
            })
            .collect()
    }

    /// The values as `f32` to change in place, converted first when held in another type.
    pub fn make_f32(&mut self) -> &mut Vec<f32> {
        if !matches!(self, Voxels::F32(_)) {
            *self = Voxels::F32(self.to_f32_vec());
        }
        match self {
            Voxels::F32(v) => v,
            _ => unreachable!("converted above"),
        }
    }

    /// Room for `additional` more values, doubling as a `Vec` would but never past `total`.
    pub(crate) fn reserve_capped(&mut self, additional: usize, total: usize) {
        dispatch!(self, v => {
            let needed = v.len() + additional;
            if needed > v.capacity() {
                let target = v.capacity().saturating_mul(2).clamp(needed, total.max(needed));
                v.reserve_exact(target - v.len());
            }
        })
    }
}

impl From<Vec<f32>> for Voxels {
    fn from(v: Vec<f32>) -> Self {
        Voxels::F32(v)
    }
}

impl FromIterator<f32> for Voxels {
    fn from_iter<I: IntoIterator<Item = f32>>(iter: I) -> Self {
        Voxels::F32(iter.into_iter().collect())
    }
}

impl From<Vec<u8>> for Voxels {
    fn from(v: Vec<u8>) -> Self {
        Voxels::U8(v)
    }
}

impl From<Vec<i8>> for Voxels {
    fn from(v: Vec<i8>) -> Self {
        Voxels::I8(v)
    }
}

impl From<Vec<u16>> for Voxels {
    fn from(v: Vec<u16>) -> Self {
        Voxels::U16(v)
    }
}

impl From<Vec<i16>> for Voxels {
    fn from(v: Vec<i16>) -> Self {
        Voxels::I16(v)
    }
}

/// Equal when they hold the same values as `f32`, whatever the types they are held in (NaN
/// unequal to itself, as for `f32`).
impl PartialEq for Voxels {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().zip(other.iter()).all(|(a, b)| a == b)
    }
}

impl PartialEq<[f32]> for Voxels {
    fn eq(&self, other: &[f32]) -> bool {
        self.len() == other.len() && self.iter().zip(other).all(|(a, &b)| a == b)
    }
}

impl<const N: usize> PartialEq<[f32; N]> for Voxels {
    fn eq(&self, other: &[f32; N]) -> bool {
        *self == other[..]
    }
}

impl PartialEq<Vec<f32>> for Voxels {
    fn eq(&self, other: &Vec<f32>) -> bool {
        *self == other[..]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_type_reads_back_as_the_same_numbers() {
        let cases: Vec<(Voxels, Vec<f32>)> = vec![
            (vec![0u8, 7, 255].into(), vec![0.0, 7.0, 255.0]),
            (vec![-128i8, 0, 127].into(), vec![-128.0, 0.0, 127.0]),
            (vec![0u16, 300, 65535].into(), vec![0.0, 300.0, 65535.0]),
            (vec![-1024i16, 0, 3071].into(), vec![-1024.0, 0.0, 3071.0]),
            (vec![-0.5f32, 1e-3, 7.25].into(), vec![-0.5, 1e-3, 7.25]),
        ];
        for (voxels, expected) in cases {
            assert_eq!(voxels.len(), 3);
            assert_eq!(voxels.to_f32_vec(), expected, "{voxels:?}");
            assert_eq!(voxels.iter().collect::<Vec<_>>(), expected);
            assert_eq!(voxels.get(1), Some(expected[1]));
            assert_eq!(voxels.get(3), None);
            let mut out = [0.0; 2];
            voxels.read(1, &mut out);
            assert_eq!(out, expected[1..]);
            assert_eq!(voxels, Voxels::F32(expected.clone()), "equal across types");
        }
    }

    #[test]
    fn runs_cover_every_value_once_in_order() {
        let voxels = Voxels::U16((0..1000).collect());
        let runs = voxels.par_chunks(64, |run| run.to_vec());
        assert_eq!(runs.len(), 16);
        assert_eq!(runs.last().map(Vec::len), Some(1000 - 15 * 64));
        let joined: Vec<f32> = runs.concat();
        assert_eq!(joined, (0..1000).map(|v| v as f32).collect::<Vec<_>>());
    }

    #[test]
    fn bytes_and_types_follow_the_stored_type() {
        assert_eq!(Voxels::U8(vec![0; 10]).bytes(), 10);
        assert_eq!(Voxels::I16(vec![0; 10]).bytes(), 20);
        assert_eq!(Voxels::new(ScalarType::F64).scalar_type(), ScalarType::F32);
        assert_eq!(Voxels::new(ScalarType::U32).scalar_type(), ScalarType::F32);
        assert_eq!(Voxels::new(ScalarType::I16).scalar_type(), ScalarType::I16);
        let mut v = Voxels::U8(vec![1, 2]);
        v.make_f32().push(0.5);
        assert_eq!(v, [1.0, 2.0, 0.5]);
    }
}
