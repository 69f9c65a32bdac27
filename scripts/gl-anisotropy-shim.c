/*
 * An LD_PRELOAD shim for reference bakes: while the environment variable
 * TESSERA_GL_MAX_ANISOTROPY is set, every glTexParameterf(…, GL_TEXTURE_MAX_ANISOTROPY, x) call
 * gets that value in place of x; unset, calls pass through unchanged.
 *
 * Why: MaterialX's GL texture handler binds every image with 16x anisotropic filtering. Mesa's
 * llvmpipe takes the anisotropic footprint from the coordinate's differences inside each 2x2
 * pixel quad, not from the gradients a shader hands to textureGrad, so where a shader's lookup
 * coordinate jumps inside a quad (hex tiling's per-tile rotation, scale and offset) the lookup
 * averages along a line across the image. scripts/mtlx_bake_refs.py bakes such shaders a second
 * time with anisotropy 1 (`isotropic_variant`); docs/materialx-conformance.md has the
 * measurements.
 *
 * MaterialX loads GL through glad, which finds its entry points with dlsym on libGL and
 * glXGetProcAddressARB, so the shim wraps dlsym and hands out its own glTexParameterf.
 * Built by scripts/mtlx-bake-refs.sh: cc -shared -fPIC -o SHIM.so gl-anisotropy-shim.c -ldl
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdlib.h>
#include <string.h>

#define GL_TEXTURE_MAX_ANISOTROPY 0x84FE

typedef void (*tex_parameter_f)(unsigned target, unsigned pname, float param);
typedef void *(*get_proc_address)(const unsigned char *name);
typedef void *(*dlsym_fn)(void *handle, const char *name);

static dlsym_fn real_dlsym;
static get_proc_address real_get_proc_address;
static tex_parameter_f real_tex_parameter_f;

static void shim_tex_parameter_f(unsigned target, unsigned pname, float param)
{
    const char *forced = getenv("TESSERA_GL_MAX_ANISOTROPY");
    if (pname == GL_TEXTURE_MAX_ANISOTROPY && forced && *forced)
        param = (float)atof(forced);
    real_tex_parameter_f(target, pname, param);
}

static void *shim_get_proc_address(const unsigned char *name)
{
    void *p = real_get_proc_address(name);
    if (p && strcmp((const char *)name, "glTexParameterf") == 0) {
        real_tex_parameter_f = (tex_parameter_f)p;
        return (void *)shim_tex_parameter_f;
    }
    return p;
}

void *dlsym(void *handle, const char *name)
{
    if (!real_dlsym)
        real_dlsym = (dlsym_fn)dlvsym(RTLD_NEXT, "dlsym", "GLIBC_2.2.5");
    void *p = real_dlsym(handle, name);
    if (!p)
        return p;
    if (strcmp(name, "glXGetProcAddressARB") == 0 || strcmp(name, "glXGetProcAddress") == 0) {
        real_get_proc_address = (get_proc_address)p;
        return (void *)shim_get_proc_address;
    }
    if (strcmp(name, "glTexParameterf") == 0) {
        real_tex_parameter_f = (tex_parameter_f)p;
        return (void *)shim_tex_parameter_f;
    }
    return p;
}

/* Lets the bake script check that the shim is loaded (it looks this symbol up). */
int tessera_gl_anisotropy_shim(void) { return 1; }
