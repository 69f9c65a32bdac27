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

/// `bjmix` of `lookup3`.
#[inline]
fn bjmix(a: &mut u32, b: &mut u32, c: &mut u32) {
    *a = a.wrapping_sub(*c);
    *a ^= c.rotate_left(4);
    *c = c.wrapping_add(*b);
    *b = b.wrapping_sub(*a);
    *b ^= a.rotate_left(6);
    *a = a.wrapping_add(*c);
    *c = c.wrapping_sub(*b);
    *c ^= b.rotate_left(8);
    *b = b.wrapping_add(*a);
    *a = a.wrapping_sub(*c);
    *a ^= c.rotate_left(16);
    *c = c.wrapping_add(*b);
    *b = b.wrapping_sub(*a);
    *b ^= a.rotate_left(19);
    *a = a.wrapping_add(*c);
    *c = c.wrapping_sub(*b);
    *c ^= b.rotate_left(4);
    *b = b.wrapping_add(*a);
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

/// Hash of four integers (one `bjmix` round, then the fourth folded into `a`).
#[inline]
pub fn hash4(x: i32, y: i32, z: i32, w: i32) -> u32 {
    let s = seed(4);
    let (mut a, mut b, mut c) = (s.wrapping_add(x as u32), s.wrapping_add(y as u32), s.wrapping_add(z as u32));
    bjmix(&mut a, &mut b, &mut c);
    a = a.wrapping_add(w as u32);
    bjfinal(a, b, c)
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

/// MaterialX `mx_cell_noise_float(vec3)` at lattice cell `(ix, iy, iz)`.
#[inline]
pub fn cell3_float(ix: i32, iy: i32, iz: i32) -> f32 {
    bits_to_01(hash3(ix, iy, iz))
}

/// Channel `k` of MaterialX `mx_cell_noise_vec3(vec3)` at lattice cell `(ix, iy, iz)`.
#[inline]
pub fn cell3_vec3(ix: i32, iy: i32, iz: i32, k: i32) -> f32 {
    bits_to_01(hash4(ix, iy, iz, k))
}

/// Channel `k` of MaterialX `mx_cell_noise_vec3(vec4)` at lattice cell `(ix, iy, iz, iw)`
/// (five-word seed; the channel offsets `b`).
#[inline]
pub fn cell4_vec3(ix: i32, iy: i32, iz: i32, iw: i32, k: u32) -> f32 {
    let s = seed(5);
    let (mut a, mut b, mut c) = (s.wrapping_add(ix as u32), s.wrapping_add(iy as u32), s.wrapping_add(iz as u32));
    bjmix(&mut a, &mut b, &mut c);
    a = a.wrapping_add(iw as u32);
    bits_to_01(bjfinal(a, b.wrapping_add(k), c))
}

/// MaterialX `mx_cell_noise_float(vec4)` at lattice cell `(ix, iy, iz, iw)`.
#[inline]
pub fn cell4_float(ix: i32, iy: i32, iz: i32, iw: i32) -> f32 {
    bits_to_01(hash4(ix, iy, iz, iw))
}
