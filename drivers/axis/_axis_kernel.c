/* rtseg.drivers.axis._axis_kernel: the Axis decoder's per-frame Euler -> quaternion ->
 * forward-kinematics loop in C (optional; rtseg.drivers.axis.codec falls back to numpy).
 *
 * Why: for one frame the numpy path is ~20 calls at their per-call floor (~24 us of a
 * ~52 us text frame); this loop does the same arithmetic in ~2 us.
 *
 * Conventions (those of codec_axis): quaternions scalar-last (x, y, z, w), float64;
 * global_j = global_parent(j) (x) local_j (Hamilton product), parents before children.
 *
 * Local quaternions are computed exactly as numpy computes them in codec_axis
 * (_half_terms, then the +-1 table of _euler_tables): pair = u_a u_b, term = pair u_c,
 * component = term_i + s term_j (a zero as +0.0, as numpy's matmul sums it), so the
 * bits are numpy's.  The forward
 * kinematics composes joint by joint; the numpy pointer jumping associates the products
 * differently (last-bit differences), so codec_axis uses one or the other for every path.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

/* (x, y, z, w) r = a (x) b */
static inline void qmul(const double *a, const double *b, double *r)
{
    const double ax = a[0], ay = a[1], az = a[2], aw = a[3];
    const double bx = b[0], by = b[1], bz = b[2], bw = b[3];
    r[0] = aw * bx + ax * bw + ay * bz - az * by;
    r[1] = aw * by - ax * bz + ay * bw + az * bx;
    r[2] = aw * bz + ax * by - ay * bx + az * bw;
    r[3] = aw * bw - ax * bx - ay * by - az * bz;
}

/* parents: int64 buffer of J entries, each -1 or < its index */
static int check_parents(const Py_buffer *pb, Py_ssize_t *J)
{
    if (pb->len % (Py_ssize_t)sizeof(long long)) {
        PyErr_SetString(PyExc_ValueError, "parents must be an int64 buffer");
        return -1;
    }
    const long long *p = (const long long *)pb->buf;
    *J = pb->len / (Py_ssize_t)sizeof(long long);
    for (Py_ssize_t j = 0; j < *J; j++) {
        if (p[j] < -1 || p[j] >= j) {
            PyErr_SetString(PyExc_ValueError, "each parent must be -1 or precede its joint");
            return -1;
        }
    }
    return 0;
}

static void compose(const long long *parents, Py_ssize_t J, const double *local,
                    Py_ssize_t row_stride, double *global)
{
    for (Py_ssize_t j = 0; j < J; j++) {
        const double *l = local + j * row_stride;
        double *g = global + 4 * j;
        const long long p = parents[j];
        if (p < 0)
            memcpy(g, l, 4 * sizeof(double));
        else
            qmul(global + 4 * p, l, g);
    }
}

/* fk(local, row_stride, frame_stride, parents, out): out[f, j] = global quaternion of
 * joint j in frame f from local[f * frame_stride + j * row_stride + 0..3] (float64). */
static PyObject *fk(PyObject *self, PyObject *args)
{
    Py_buffer lb, pb, ob;
    Py_ssize_t row_stride, frame_stride, J;
    if (!PyArg_ParseTuple(args, "y*nny*w*", &lb, &row_stride, &frame_stride, &pb, &ob))
        return NULL;
    PyObject *ret = NULL;
    if (check_parents(&pb, &J) < 0)
        goto done;
    Py_ssize_t n_local = lb.len / (Py_ssize_t)sizeof(double);
    Py_ssize_t n_out = ob.len / (Py_ssize_t)sizeof(double);
    if (J == 0 || row_stride < 4 || frame_stride < J * row_stride || n_out % (4 * J)) {
        PyErr_SetString(PyExc_ValueError, "fk: inconsistent strides or sizes");
        goto done;
    }
    Py_ssize_t F = n_out / (4 * J);
    if (F && (F - 1) * frame_stride + (J - 1) * row_stride + 4 > n_local) {
        PyErr_SetString(PyExc_ValueError, "fk: local buffer too short");
        goto done;
    }
    const long long *parents = (const long long *)pb.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t f = 0; f < F; f++)
        compose(parents, J, (const double *)lb.buf + f * frame_stride, row_stride,
                (double *)ob.buf + f * 4 * J);
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyBuffer_Release(&lb);
    PyBuffer_Release(&pb);
    PyBuffer_Release(&ob);
    return ret;
}

/* numpy's sum of the 8 products t[k] * T[k, col] where only t_i (+1) and t_j (s = +-1) are
 * nonzero in the table: the other products are zeros, which leave a nonzero sum exact;
 * a zero sum is +0.0 (numpy's matmul, with or without BLAS, accumulates from +0.0, and
 * +0.0 + -0.0 = +0.0). */
static inline double table_sum(const double *t, int i, int j, double s)
{
    return (t[i] + s * t[j]) + 0.0;
}

/* euler_fk(u, n_per_frame, a, b, c, eps, parents, local_out, global_out)
 * u: (6, N) float64 rows cos a, cos b, cos c, sin a, sin b, sin c of N triples, frames of
 * n_per_frame triples (J joints, then any extra columns, e.g. an identity, skipped);
 * a, b, c: the order's axes (0 x, 1 y, 2 z); eps: its parity (+1 cyclic);
 * local_out, global_out: (F, J, 4) float64. */
static PyObject *euler_fk(PyObject *self, PyObject *args)
{
    Py_buffer ub, pb, lb, gb;
    Py_ssize_t per_frame, J;
    int a, b, c;
    double eps;
    if (!PyArg_ParseTuple(args, "y*niiidy*w*w*", &ub, &per_frame, &a, &b, &c, &eps, &pb,
                          &lb, &gb))
        return NULL;
    PyObject *ret = NULL;
    if (check_parents(&pb, &J) < 0)
        goto done;
    Py_ssize_t N = ub.len / (Py_ssize_t)(6 * sizeof(double));
    Py_ssize_t n_out = lb.len / (Py_ssize_t)sizeof(double);
    if (a < 0 || a > 2 || b < 0 || b > 2 || c < 0 || c > 2 || a == b || b == c || a == c
        || (eps != 1.0 && eps != -1.0)) {
        PyErr_SetString(PyExc_ValueError, "euler_fk: bad axis order");
        goto done;
    }
    if (J == 0 || per_frame < J || N % per_frame || n_out != (N / per_frame) * 4 * J
        || gb.len != lb.len || ub.len != N * 6 * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "euler_fk: inconsistent sizes");
        goto done;
    }
    const double *u = (const double *)ub.buf;
    const long long *parents = (const long long *)pb.buf;
    double *loc = (double *)lb.buf, *glob = (double *)gb.buf;
    Py_ssize_t F = N / per_frame;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t f = 0; f < F; f++) {
        for (Py_ssize_t j = 0; j < J; j++) {
            const Py_ssize_t n = f * per_frame + j;
            const double ca = u[n], cb = u[N + n], cc = u[2 * N + n];
            const double sa = u[3 * N + n], sb = u[4 * N + n], sc = u[5 * N + n];
            /* codec_axis._half_terms: pairs ca cb, ca sb, sa cb, sa sb; times cc, sc */
            const double p0 = ca * cb, p1 = ca * sb, p2 = sa * cb, p3 = sa * sb;
            const double t[8] = {p0 * cc, p0 * sc, p1 * cc, p1 * sc,
                                 p2 * cc, p2 * sc, p3 * cc, p3 * sc};
            double *q = loc + 4 * (f * J + j);
            /* codec_axis._euler_tables */
            q[3] = table_sum(t, 0, 7, -eps);
            q[a] = table_sum(t, 4, 3, eps);
            q[b] = table_sum(t, 2, 5, -eps);
            q[c] = table_sum(t, 1, 6, eps);
        }
        compose(parents, J, loc + 4 * f * J, 4, glob + 4 * f * J);
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyBuffer_Release(&ub);
    PyBuffer_Release(&pb);
    PyBuffer_Release(&lb);
    PyBuffer_Release(&gb);
    return ret;
}

static PyMethodDef methods[] = {
    {"fk", fk, METH_VARARGS,
     "fk(local, row_stride, frame_stride, parents, out): global quaternions (F, J, 4) from "
     "local ones, joint by joint (float64 buffers; parents int64, each before its joint)."},
    {"euler_fk", euler_fk, METH_VARARGS,
     "euler_fk(u, n_per_frame, a, b, c, eps, parents, local_out, global_out): local and "
     "global quaternions from the half-angle cosines and sines u (6, N)."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_axis_kernel",
                                    "Axis Euler -> quaternion -> forward kinematics in C.",
                                    -1, methods};

PyMODINIT_FUNC PyInit__axis_kernel(void) { return PyModule_Create(&module); }
