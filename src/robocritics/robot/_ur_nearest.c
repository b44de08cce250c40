/* The UR closed form searched for the branch nearest a seed, compiled: robocritics.robot.ik_nearest's
 * _nearest_search_plain (unverified) step for step, the same expressions in the same order on IEEE doubles, so
 * the same floats (tests/test_ik_nearest_compiled.py compares the two bit for bit). Units: m, rad.
 *
 * Why compiled: on CPython one solve of the Python search executes about 1,200 bytecodes (50,000 machine
 * instructions, 5-8 us); the same arithmetic in C is about 0.2 us. Only the common case is here: a target with
 * a finite pose, seed, limits and weights and a wrist away from its singularity (|sin q5| >= the near-singular
 * threshold on every shoulder pan searched). Anything else returns NotImplemented and the caller runs the Python
 * search, which stays the reference. Built with -ffp-contract=off (no fused multiply-add: Python rounds each
 * product) and -fno-builtin (libm's sin and cos, as Python's math module calls them). */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

static double PI, TWO_PI, HALF_PI;  /* set from Python's math.pi at import: the same floats */
static double CLIP_TOL, WRIST_NEAR_SINGULAR, WRIST_SINGULAR, LIMIT_SLACK;  /* from ik_many, by configure() */
static int configured = 0;

typedef struct {
    double k[8], t[12], sd[6], lo[6], hi[6], w[6];
    double best;    /* cost of the best complete branch so far (inf: none) */
    double q[6];    /* its joints */
    int exact;      /* its exact flag */
    int bail;       /* the common case does not hold: the caller runs the Python search */
} Search;

/* Python's math.atan2 (mathmodule.c m_atan2): libm's, with C99's special cases made explicit. */
static double py_atan2(double y, double x) {
    if (isnan(x) || isnan(y)) return NAN;
    if (isinf(y)) {
        if (isinf(x)) return copysign(copysign(1., x) == 1. ? 0.25 * PI : 0.75 * PI, y);
        return copysign(0.5 * PI, y);
    }
    if (isinf(x) || y == 0.) return copysign(1., x) == 1. ? copysign(0., y) : copysign(PI, y);
    return atan2(y, x);
}

/* Python's round(x) of a float (round half to even), as a double. */
static double py_round(double x) {
    double rounded = round(x);
    if (fabs(x - rounded) == 0.5) rounded = 2.0 * round(x / 2.0);
    return rounded;
}

/* ik_nearest._nearest_equivalent: 1 and *v, or 0 if no equivalent fits. */
static int nearest_equivalent(double x, double seed, double lo, double hi, double *v) {
    double u = x + py_round((seed - x) / TWO_PI) * TWO_PI;
    if (lo <= u && u <= hi) { *v = u; return 1; }
    double n_min = ceil((lo - LIMIT_SLACK - x) / TWO_PI);
    double n_max = floor((hi + LIMIT_SLACK - x) / TWO_PI);
    if (n_min > n_max) return 0;
    u = x + (u > hi ? n_max : n_min) * TWO_PI;
    *v = u > hi ? hi : (u < lo ? lo : u);
    return 1;
}

/* ik_nearest._off_seed: *v (valid when the return is 1), *c = cost + w (v - seed)² or inf, *exact. */
static int off_seed(double x, double seed, double lo, double hi, double w, double cost, double *v, double *c,
                    int *exact) {
    double n = (seed - x) / TWO_PI, u;
    if (0.5 < n && n < 1.5) u = x + TWO_PI;
    else if (-1.5 < n && n < -0.5) u = x - TWO_PI;
    else u = x + py_round(n) * TWO_PI;
    if (lo <= u && u <= hi) { *v = u; *c = cost + w * (u - seed) * (u - seed); *exact = 1; return 1; }
    if (!nearest_equivalent(x, seed, lo, hi, &u)) { *c = INFINITY; *exact = 0; return 0; }
    *v = u; *c = cost + w * (u - seed) * (u - seed); *exact = !(u == lo || u == hi);
    return 1;
}

/* One angle moved to its seed-nearest equivalent (the fast path inline, as in the Python search): the joint j's
 * *v and *c = cost + w_j (v - s_j)²; *e &= exact. Returns whether an equivalent fits. */
static inline int angle(const Search *S, int j, double x, double cost, double *v, double *c, int *e) {
    double s = S->sd[j], d = s - x;
    if (-PI < d && d < PI && S->lo[j] <= x && x <= S->hi[j]) { *v = x; *c = cost + S->w[j] * d * d; return 1; }
    int ex, ok = off_seed(x, s, S->lo[j], S->hi[j], S->w[j], cost, v, c, &ex);
    *e = *e && ex;
    return ok;
}

/* ik_nearest._nearest_elbow, the wrist away from its singularity (v6 known, its cost in cost56). */
static void elbow(Search *S, double c1, double s1, double p5x, double p5y, double q5, double q6, double v1,
                  double v5, double v6, double cost56, int exact) {
    const double *k = S->k, *t = S->t;
    double d1 = k[0], a2 = k[1], a3 = k[2], d5 = k[4], d6 = k[5], a2a3_sq = k[6], two_a2a3 = k[7];
    double xx = t[0], yx = t[1], zx = t[2], xy = t[4], yy = t[5], zy = t[6], xz = t[8], yz = t[9], zz = t[10],
           pz = t[11];
    double c6 = cos(q6), s6 = sin(q6);
    double z4x = -(s6 * xx + c6 * yx), z4y = -(s6 * xy + c6 * yy), z4z = -(s6 * xz + c6 * yz);
    double X = (p5x - d5 * z4x) * c1 + (p5y - d5 * z4y) * s1;
    double Y = pz - d6 * zz - d5 * z4z - d1;
    double c3 = (X * X + Y * Y - a2a3_sq) / two_a2a3;
    if (!(-1.0 <= c3 && c3 <= 1.0)) {
        exact = 0;
        if (!(-1.0 - CLIP_TOL <= c3 && c3 <= 1.0 + CLIP_TOL)) return;
        c3 = c3 > 1.0 ? 1.0 : -1.0;
    }
    double t3 = acos(c3), v3p, cp, v3m, cm;
    int ep = exact, em = exact;
    angle(S, 2, t3, cost56, &v3p, &cp, &ep);
    angle(S, 2, -t3, cost56, &v3m, &cm, &em);
    if (cp >= S->best && cm >= S->best) return;
    double c5 = cos(q5), s5 = sin(q5);
    double x4x = c5 * (c6 * xx - s6 * yx) - s5 * zx;
    double x4y = c5 * (c6 * xy - s6 * yy) - s5 * zy;
    double x4z = c5 * (c6 * xz - s6 * yz) - s5 * zz;
    double base = py_atan2(Y, X);
    double q234 = py_atan2(x4z, x4x * c1 + x4y * s1);
    int minus_first = cm < cp;
    for (int i = 0; i < 2; i++) {
        int minus = (i == 0) == minus_first;
        double cost3 = minus ? cm : cp, q3 = minus ? -t3 : t3, v3 = minus ? v3m : v3p;
        int e3 = minus ? em : ep;
        if (cost3 >= S->best) break;
        double q2 = base - py_atan2(a3 * sin(q3), a2 + a3 * c3), v2, cost2, v4, cost;
        if (!angle(S, 1, q2, cost3, &v2, &cost2, &e3)) continue;
        if (cost2 >= S->best) continue;
        double q4 = q234 - q2 - q3;
        if (!angle(S, 3, q4, cost2, &v4, &cost, &e3)) continue;
        if (cost < S->best) {
            S->best = cost;
            S->q[0] = v1; S->q[1] = v2; S->q[2] = v3; S->q[3] = v4; S->q[4] = v5; S->q[5] = v6;
            S->exact = e3;
        }
    }
}

/* ik_nearest._nearest_wrists for the shoulder pan q1 (its equivalent v1 costs cost1). */
static void wrists(Search *S, double p5x, double p5y, double q1, double v1, double cost1, int exact) {
    const double *t = S->t;
    double c1 = cos(q1), s1 = sin(q1);
    double xz1 = t[0] * s1 - t[4] * c1, yz1 = t[1] * s1 - t[5] * c1, zz1 = t[2] * s1 - t[6] * c1;
    double s5abs = sqrt(xz1 * xz1 + yz1 * yz1);
    if (s5abs < WRIST_NEAR_SINGULAR) { S->bail = 1; return; }  /* q6 may be nudged: the Python search's case */
    double q5u = py_atan2(s5abs, zz1), q6u = py_atan2(-yz1, xz1), v5u, v6u = 0.0, cu;
    int eu = exact;
    if (angle(S, 4, q5u, cost1, &v5u, &cu, &eu)) angle(S, 5, q6u, cu, &v6u, &cu, &eu);
    double q5d = py_atan2(-s5abs, zz1), v5d, v6d = 0.0, cd;
    int ed = exact, down_ok = angle(S, 4, q5d, cost1, &v5d, &cd, &ed);
    int up_done = cu <= cd;
    if (up_done) {
        if (cu >= S->best) return;
        elbow(S, c1, s1, p5x, p5y, q5u, q6u, v1, v5u, v6u, cu, eu);
        if (cd >= S->best) return;
    }
    double q6d = py_atan2(yz1, -xz1);
    if (down_ok) angle(S, 5, q6d, cd, &v6d, &cd, &ed);
    if (!up_done && !(cd < cu)) {
        if (cu >= S->best) return;
        elbow(S, c1, s1, p5x, p5y, q5u, q6u, v1, v5u, v6u, cu, eu);
        up_done = 1;
    }
    if (cd < S->best) elbow(S, c1, s1, p5x, p5y, q5d, q6d, v1, v5d, v6d, cd, ed);
    if (!up_done && cu < S->best) elbow(S, c1, s1, p5x, p5y, q5u, q6u, v1, v5u, v6u, cu, eu);
}

/* Reads n floats of a list or tuple into out; 0 (with an exception set) if it is not one of n floats. */
static int read_floats(PyObject *seq, double *out, Py_ssize_t n) {
    PyObject *fast = PySequence_Fast(seq, "expected a sequence of floats");
    if (fast == NULL) return 0;
    int ok = PySequence_Fast_GET_SIZE(fast) == n;
    PyObject **items = PySequence_Fast_ITEMS(fast);
    for (Py_ssize_t i = 0; ok && i < n; i++) {
        out[i] = PyFloat_AsDouble(items[i]);
        if (out[i] == -1.0 && PyErr_Occurred()) ok = 0;
    }
    Py_DECREF(fast);
    if (!ok && !PyErr_Occurred()) PyErr_Format(PyExc_ValueError, "expected %zd floats", n);
    return ok;
}

static PyObject *nearest_search(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 6) { PyErr_SetString(PyExc_TypeError, "nearest_search(k, t, sd, lo, hi, w)"); return NULL; }
    if (!configured) { PyErr_SetString(PyExc_RuntimeError, "configure() first"); return NULL; }
    Search S;
    if (!read_floats(args[0], S.k, 8) || !read_floats(args[1], S.t, 12) || !read_floats(args[2], S.sd, 6) ||
        !read_floats(args[3], S.lo, 6) || !read_floats(args[4], S.hi, 6) || !read_floats(args[5], S.w, 6))
        return NULL;
    for (int i = 0; i < 12; i++) if (!isfinite(S.t[i])) Py_RETURN_NOTIMPLEMENTED;
    for (int i = 0; i < 6; i++)
        if (!isfinite(S.sd[i]) || !isfinite(S.lo[i]) || !isfinite(S.hi[i]) || !isfinite(S.w[i]))
            Py_RETURN_NOTIMPLEMENTED;
    S.best = INFINITY; S.bail = 0; S.exact = 0;
    const double *k = S.k, *t = S.t;
    double d6 = k[5];
    double p5x = t[3] - d6 * t[2], p5y = t[7] - d6 * t[6];
    double r = sqrt(p5x * p5x + p5y * p5y);
    if (r == 0.0) Py_RETURN_NONE;
    double ratio = k[3] / r;
    int exact = -1.0 <= ratio && ratio <= 1.0;
    if (!exact) {
        if (!(-1.0 - CLIP_TOL <= ratio && ratio <= 1.0 + CLIP_TOL)) Py_RETURN_NONE;
        ratio = ratio > 1.0 ? 1.0 : -1.0;
    }
    double phi = py_atan2(p5y, p5x) + HALF_PI, dphi = acos(ratio);
    double qa = phi + dphi, qb = phi - dphi, va = 0.0, vb = 0.0, ca, cb;
    int ea = 1, eb = 1;
    angle(&S, 0, qa, 0.0, &va, &ca, &ea);
    angle(&S, 0, qb, 0.0, &vb, &cb, &eb);
    if (cb < ca) {
        double tq = qa, tv = va, tc = ca; int te = ea;
        qa = qb; va = vb; ca = cb; ea = eb; qb = tq; vb = tv; cb = tc; eb = te;
    }
    if (ca == INFINITY) Py_RETURN_NONE;
    wrists(&S, p5x, p5y, qa, va, ca, exact && ea);
    if (!S.bail && cb < S.best) wrists(&S, p5x, p5y, qb, vb, cb, exact && eb);
    if (S.bail) Py_RETURN_NOTIMPLEMENTED;
    if (S.best == INFINITY) Py_RETURN_NONE;
    PyObject *q = PyList_New(6);
    if (q == NULL) return NULL;
    for (int i = 0; i < 6; i++) {
        PyObject *f = PyFloat_FromDouble(S.q[i]);
        if (f == NULL) { Py_DECREF(q); return NULL; }
        PyList_SET_ITEM(q, i, f);
    }
    return Py_BuildValue("(dNO)", S.best, q, S.exact ? Py_True : Py_False);
}

static PyObject *configure(PyObject *self, PyObject *args) {
    if (!PyArg_ParseTuple(args, "ddddd", &PI, &CLIP_TOL, &WRIST_NEAR_SINGULAR, &WRIST_SINGULAR, &LIMIT_SLACK))
        return NULL;
    TWO_PI = 2.0 * PI;
    HALF_PI = 0.5 * PI;
    configured = 1;
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"nearest_search", (PyCFunction)(void (*)(void))nearest_search, METH_FASTCALL,
     "nearest_search(k, t, sd, lo, hi, w) -> (cost, q, exact), None, or NotImplemented (run the Python search)"},
    {"configure", configure, METH_VARARGS, "configure(pi, clip_tol, wrist_near_singular, wrist_singular, limit_slack)"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_ur_nearest", NULL, -1, methods};

PyMODINIT_FUNC PyInit__ur_nearest(void) { return PyModule_Create(&module); }
