//! MaterialX's integer hash (Bob Jenkins' `lookup3` final mix, as in OSL) and the derived
//! cell values, reproduced bit for bit so that bakes match.

/// `bjfinal` of `lookup3`.
#[inline]
fn bjfinal(mut a: u32, mut b: u32, mut c: u32) -> u32 {
    c ^= b;
    c = c.wrapping_sub(b.rotate_left(14));
    a ^= c;
    a = a.wrapping_sub(c.rotate_left(11));
    b ^= a;
    b = b.wrapping_sub(a.rotate_left(25));
    c ^= b;
    c = c.wrapping_sub(b.rotate_left(16));
    a ^= c;
    a = a.wrapping_sub(c.rotate_left(4));
    b ^= a;
    b = b.wrapping_sub(a.rotate_left(14));
    c ^= b;
    c = c.wrapping_sub(b.rotate_left(24));
    c
}

const fn seed(len: u32) -> u32 {
    0xdead_beef_u32.wrapping_add(len << 2).wrapping_add(13)
}

/// Hash of two integers.
#[inline]
pub fn hash2(x: i32, y: i32) -> u32 {
    let s = seed(2);
    bjfinal(s.wrapping_add(x as u32), s.wrapping_add(y as u32), s)
}

/// Hash of three integers.
#[inline]
pub fn hash3(x: i32, y: i32, z: i32) -> u32 {
    let s = seed(3);
    bjfinal(s.wrapping_add(x as u32), s.wrapping_add(y as u32), s.wrapping_add(z as u32))
}

/// A hash as a float in [0, 1], rounded the way GLSL's `float(uint) / float(0xffffffffu)` does.
#[inline]
pub fn bits_to_01(bits: u32) -> f32 {
    bits as f32 / 4_294_967_295u32 as f32
}

/// `floor` to an integer lattice coordinate.
#[inline]
pub fn ifloor(x: f32) -> i32 {
    x.floor() as i32
}

/// MaterialX `mx_cell_noise_float(vec2)` at lattice cell `(ix, iy)`.
#[inline]
pub fn cell_float(ix: i32, iy: i32) -> f32 {
    bits_to_01(hash2(ix, iy))
}

/// Channel `k` of MaterialX `mx_cell_noise_vec3(vec2)` at lattice cell `(ix, iy)`.
#[inline]
pub fn cell_vec3(ix: i32, iy: i32, k: i32) -> f32 {
    bits_to_01(hash3(ix, iy, k))
}
