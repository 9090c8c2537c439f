/*
 * cbody: a small rigid-body simulator in C99, the worked example of an rbcheck engine file.
 *
 *   cbody SCENARIO_JSON OUT_CSV
 *
 * reads the resolved scenario JSON that rbcheck writes for each run (`rbcheck show SCENARIO --json`;
 * docs/engines.md), integrates `steps` steps of `dt` and writes the trajectory CSV
 * t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz (one row per step from t = 0, 17 significant digits).
 *
 * Scheme (global order 1): semi-implicit (symplectic) Euler with the explicit gyroscopic term and
 * the exponential-map quaternion update, all forces from the start-of-step state:
 *
 *   f, tau = forces(x, v, q)                      (world axes; torque about the COM)
 *   v <- gamma_v (v + dt f / m);   x <- x + dt v
 *   w_B = R^T w;  w <- gamma_w (w + dt R I^-1 (R^T tau - w_B x I w_B))
 *   q <- exp(dt w) (x) q, normalised               (w in WORLD axes, so exp multiplies from the left)
 *
 * Compiled with -DBROKEN_GYRO_SIGN the gyroscopic term has the wrong sign: the deliberately broken
 * copy rbcheck's tests must catch (cbody_broken.toml).
 *
 * A bad or incomplete JSON file: one line on stderr naming the field, exit status 2.
 */
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef BROKEN_GYRO_SIGN
#define GYRO_SIGN (+1.0)
#else
#define GYRO_SIGN (-1.0)
#endif

/* ---------------------------------------------------------------- a small JSON reader */

typedef enum { J_NULL, J_BOOL, J_NUM, J_STR, J_ARR, J_OBJ } jtype;

typedef struct jnode {
    jtype type;
    double num;
    char *str;             /* J_STR value; member key when inside an object */
    char *key;
    struct jnode *kids;    /* J_ARR / J_OBJ children, in order */
    int n;
} jnode;

static const char *src;    /* parse cursor */
static const char *json_path;

static void fail(const char *field, const char *why) {
    fprintf(stderr, "cbody: %s: %s: %s\n", json_path, field, why);
    exit(2);
}

static void skip_ws(void) { while (*src && isspace((unsigned char)*src)) src++; }

static void parse_value(jnode *out);

static char *parse_string(void) {
    /* Strings rbcheck writes need no escapes beyond \" \\ \/ \n \t and \uXXXX (copied verbatim). */
    if (*src != '"') fail("(syntax)", "expected a string");
    src++;
    size_t cap = 32, len = 0;
    char *s = malloc(cap);
    while (*src && *src != '"') {
        char c = *src++;
        if (c == '\\') {
            char e = *src++;
            c = e == 'n' ? '\n' : e == 't' ? '\t' : e == 'u' ? '?' : e;
            if (e == 'u') src += 4;
        }
        if (len + 2 > cap) s = realloc(s, cap *= 2);
        s[len++] = c;
    }
    if (*src != '"') fail("(syntax)", "unterminated string");
    src++;
    s[len] = 0;
    return s;
}

static void parse_list(jnode *out, char close, int with_keys) {
    src++;
    int cap = 4;
    out->kids = malloc(sizeof(jnode) * cap);
    out->n = 0;
    skip_ws();
    if (*src == close) { src++; return; }
    for (;;) {
        if (out->n == cap) out->kids = realloc(out->kids, sizeof(jnode) * (cap *= 2));
        jnode *kid = &out->kids[out->n++];
        memset(kid, 0, sizeof *kid);
        skip_ws();
        if (with_keys) {
            char *key = parse_string();
            skip_ws();
            if (*src++ != ':') fail("(syntax)", "expected ':'");
            parse_value(kid);
            kid->key = key;
        } else {
            parse_value(kid);
        }
        skip_ws();
        if (*src == ',') { src++; continue; }
        if (*src == close) { src++; return; }
        fail("(syntax)", "expected ',' or a closing bracket");
    }
}

static void parse_value(jnode *out) {
    skip_ws();
    memset(out, 0, sizeof *out);
    if (*src == '{') { out->type = J_OBJ; parse_list(out, '}', 1); }
    else if (*src == '[') { out->type = J_ARR; parse_list(out, ']', 0); }
    else if (*src == '"') { out->type = J_STR; out->str = parse_string(); }
    else if (!strncmp(src, "true", 4)) { out->type = J_BOOL; out->num = 1; src += 4; }
    else if (!strncmp(src, "false", 5)) { out->type = J_BOOL; src += 5; }
    else if (!strncmp(src, "null", 4)) { out->type = J_NULL; src += 4; }
    else {
        char *end;
        errno = 0;
        out->num = strtod(src, &end);
        if (end == src) fail("(syntax)", "unexpected character");
        out->type = J_NUM;
        src = end;
    }
}

static const jnode *member(const jnode *obj, const char *key, const char *field) {
    if (obj->type != J_OBJ) fail(field, "expected an object");
    for (int i = 0; i < obj->n; i++)
        if (!strcmp(obj->kids[i].key, key)) return &obj->kids[i];
    fail(field, "missing");
    return NULL;
}

static double number(const jnode *obj, const char *key, const char *field) {
    const jnode *v = member(obj, key, field);
    if (v->type != J_NUM) fail(field, "expected a number");
    return v->num;
}

static void vector(const jnode *obj, const char *key, int n, double *out, const char *field) {
    const jnode *v = member(obj, key, field);
    if (v->type != J_ARR || v->n != n) fail(field, n == 3 ? "expected 3 numbers" : "expected 4 numbers");
    for (int i = 0; i < n; i++) {
        if (v->kids[i].type != J_NUM) fail(field, "expected numbers");
        out[i] = v->kids[i].num;
    }
}

static int is_body_frame(const jnode *item, const char *field) {
    const jnode *f = member(item, "frame", field);
    if (f->type != J_STR || (strcmp(f->str, "world") && strcmp(f->str, "body")))
        fail(field, "frame must be \"world\" or \"body\"");
    return !strcmp(f->str, "body");
}

/* ---------------------------------------------------------------- 3-vectors, 3x3, quaternions */

static void cross(const double a[3], const double b[3], double out[3]) {
    double c[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    memcpy(out, c, sizeof c);
}

static void matvec(const double M[3][3], const double a[3], double out[3]) {
    for (int i = 0; i < 3; i++) out[i] = M[i][0] * a[0] + M[i][1] * a[1] + M[i][2] * a[2];
}

static void mattvec(const double M[3][3], const double a[3], double out[3]) {
    for (int i = 0; i < 3; i++) out[i] = M[0][i] * a[0] + M[1][i] * a[1] + M[2][i] * a[2];
}

static void inverse3(const double M[3][3], double out[3][3]) {
    double c00 = M[1][1] * M[2][2] - M[1][2] * M[2][1], c01 = M[1][2] * M[2][0] - M[1][0] * M[2][2],
           c02 = M[1][0] * M[2][1] - M[1][1] * M[2][0];
    double det = M[0][0] * c00 + M[0][1] * c01 + M[0][2] * c02;
    out[0][0] = c00 / det;
    out[1][0] = c01 / det;
    out[2][0] = c02 / det;
    out[0][1] = (M[0][2] * M[2][1] - M[0][1] * M[2][2]) / det;
    out[1][1] = (M[0][0] * M[2][2] - M[0][2] * M[2][0]) / det;
    out[2][1] = (M[0][1] * M[2][0] - M[0][0] * M[2][1]) / det;
    out[0][2] = (M[0][1] * M[1][2] - M[0][2] * M[1][1]) / det;
    out[1][2] = (M[0][2] * M[1][0] - M[0][0] * M[1][2]) / det;
    out[2][2] = (M[0][0] * M[1][1] - M[0][1] * M[1][0]) / det;
}

/* Rotation matrix of a unit quaternion (w, x, y, z), body -> world. */
static void quat_matrix(const double q[4], double R[3][3]) {
    double w = q[0], x = q[1], y = q[2], z = q[3];
    R[0][0] = 1 - 2 * (y * y + z * z); R[0][1] = 2 * (x * y - w * z);     R[0][2] = 2 * (x * z + w * y);
    R[1][0] = 2 * (x * y + w * z);     R[1][1] = 1 - 2 * (x * x + z * z); R[1][2] = 2 * (y * z - w * x);
    R[2][0] = 2 * (x * z - w * y);     R[2][1] = 2 * (y * z + w * x);     R[2][2] = 1 - 2 * (x * x + y * y);
}

static void quat_mul(const double a[4], const double b[4], double out[4]) {
    double r[4] = {a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
                   a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
                   a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
                   a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]};
    memcpy(out, r, sizeof r);
}

/* exp of a rotation vector (rad): [cos(th/2), sin(th/2)/th * r], a series near 0. */
static void quat_exp(const double r[3], double out[4]) {
    double th = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    double t2 = th * th;
    double s = th < 1e-4 ? 0.5 - t2 / 48.0 + t2 * t2 / 3840.0 : sin(0.5 * th) / th;
    out[0] = cos(0.5 * th);
    out[1] = s * r[0];
    out[2] = s * r[1];
    out[3] = s * r[2];
}

/* ---------------------------------------------------------------- the scenario and its forces */

typedef struct { double anchor[3], attach[3], k, rest; } spring_t;
typedef struct { double force[3], point[3]; int body; } point_t;
typedef struct { double torque[3]; int body; } torque_t;

typedef struct {
    double dt, mass, I[3][3], Iinv[3][3], gravity[3], drag, decay_v, decay_w;
    long steps;
    double x[3], v[3], q[4], w[3];
    spring_t *springs; int n_springs;
    point_t *points; int n_points;
    torque_t *torques; int n_torques;
} scenario_t;

static void read_scenario(const jnode *root, scenario_t *s) {
    s->dt = number(root, "dt", "dt");
    double steps = number(root, "steps", "steps");
    if (!(s->dt > 0) || steps < 0 || steps != floor(steps)) fail("dt/steps", "need dt > 0 and a whole number of steps");
    s->steps = (long)steps;
    const jnode *body = member(root, "body", "body");
    s->mass = number(body, "mass", "body.mass");
    const jnode *I = member(body, "inertia", "body.inertia");
    if (I->type != J_ARR || I->n != 3) fail("body.inertia", "expected a 3x3 matrix");
    for (int i = 0; i < 3; i++) {
        const jnode *row = &I->kids[i];
        if (row->type != J_ARR || row->n != 3) fail("body.inertia", "expected a 3x3 matrix");
        for (int j = 0; j < 3; j++) s->I[i][j] = row->kids[j].num;
    }
    inverse3(s->I, s->Iinv);
    const jnode *ini = member(root, "initial", "initial");
    vector(ini, "position", 3, s->x, "initial.position");
    vector(ini, "velocity", 3, s->v, "initial.velocity");
    vector(ini, "orientation", 4, s->q, "initial.orientation");
    vector(ini, "angular_velocity", 3, s->w, "initial.angular_velocity");
    const jnode *f = member(root, "forces", "forces");
    vector(f, "gravity", 3, s->gravity, "forces.gravity");
    s->drag = number(f, "linear_drag", "forces.linear_drag");
    s->decay_v = number(f, "velocity_decay", "forces.velocity_decay");
    s->decay_w = number(f, "angular_velocity_decay", "forces.angular_velocity_decay");
    const jnode *sp = member(f, "spring", "forces.spring"), *pt = member(f, "point", "forces.point"),
                *tq = member(f, "torque", "forces.torque");
    s->n_springs = sp->n; s->n_points = pt->n; s->n_torques = tq->n;
    s->springs = calloc(sp->n + 1, sizeof(spring_t));
    s->points = calloc(pt->n + 1, sizeof(point_t));
    s->torques = calloc(tq->n + 1, sizeof(torque_t));
    for (int i = 0; i < sp->n; i++) {
        vector(&sp->kids[i], "anchor", 3, s->springs[i].anchor, "forces.spring[].anchor");
        vector(&sp->kids[i], "attach", 3, s->springs[i].attach, "forces.spring[].attach");
        s->springs[i].k = number(&sp->kids[i], "stiffness", "forces.spring[].stiffness");
        s->springs[i].rest = number(&sp->kids[i], "rest_length", "forces.spring[].rest_length");
    }
    for (int i = 0; i < pt->n; i++) {
        vector(&pt->kids[i], "force", 3, s->points[i].force, "forces.point[].force");
        vector(&pt->kids[i], "point", 3, s->points[i].point, "forces.point[].point");
        s->points[i].body = is_body_frame(&pt->kids[i], "forces.point[].frame");
    }
    for (int i = 0; i < tq->n; i++) {
        vector(&tq->kids[i], "torque", 3, s->torques[i].torque, "forces.torque[].torque");
        s->torques[i].body = is_body_frame(&tq->kids[i], "forces.torque[].frame");
    }
}

/* World force at the COM and world torque about it, from the state (x, v) and rotation R. */
static void forces(const scenario_t *s, const double x[3], const double v[3], const double R[3][3],
                   double f[3], double tau[3]) {
    for (int i = 0; i < 3; i++) { f[i] = s->mass * s->gravity[i] - s->drag * v[i]; tau[i] = 0.0; }
    for (int k = 0; k < s->n_springs; k++) {
        const spring_t *sp = &s->springs[k];
        double r[3], d[3], fs[3], t[3];
        matvec(R, sp->attach, r);
        for (int i = 0; i < 3; i++) d[i] = x[i] + r[i] - sp->anchor[i];
        double L = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        if (L == 0.0) continue;
        for (int i = 0; i < 3; i++) fs[i] = -sp->k * (L - sp->rest) * d[i] / L;
        cross(r, fs, t);
        for (int i = 0; i < 3; i++) { f[i] += fs[i]; tau[i] += t[i]; }
    }
    for (int k = 0; k < s->n_points; k++) {
        const point_t *p = &s->points[k];
        double F[3], r[3], t[3];
        if (p->body) matvec(R, p->force, F); else memcpy(F, p->force, sizeof F);
        matvec(R, p->point, r);
        cross(r, F, t);
        for (int i = 0; i < 3; i++) { f[i] += F[i]; tau[i] += t[i]; }
    }
    for (int k = 0; k < s->n_torques; k++) {
        const torque_t *t = &s->torques[k];
        double T[3];
        if (t->body) matvec(R, t->torque, T); else memcpy(T, t->torque, sizeof T);
        for (int i = 0; i < 3; i++) tau[i] += T[i];
    }
}

static void step(scenario_t *s) {
    double R[3][3], f[3], tau[3], wB[3], IwB[3], gyro[3], tauB[3], aB[3], aW[3], rv[3], dq[4];
    double h = s->dt;
    quat_matrix(s->q, R);
    forces(s, s->x, s->v, R, f, tau);
    for (int i = 0; i < 3; i++) {
        s->v[i] = s->decay_v * (s->v[i] + h * f[i] / s->mass);
        s->x[i] += h * s->v[i];
    }
    mattvec(R, s->w, wB);
    matvec(s->I, wB, IwB);
    cross(wB, IwB, gyro);
    mattvec(R, tau, tauB);
    for (int i = 0; i < 3; i++) tauB[i] += GYRO_SIGN * gyro[i];
    matvec(s->Iinv, tauB, aB);
    matvec(R, aB, aW);
    for (int i = 0; i < 3; i++) {
        s->w[i] = s->decay_w * (s->w[i] + h * aW[i]);
        rv[i] = h * s->w[i];
    }
    quat_exp(rv, dq);
    quat_mul(dq, s->q, s->q);
    double n = sqrt(s->q[0] * s->q[0] + s->q[1] * s->q[1] + s->q[2] * s->q[2] + s->q[3] * s->q[3]);
    for (int i = 0; i < 4; i++) s->q[i] /= n;
}

static void write_row(FILE *out, double t, const scenario_t *s) {
    fprintf(out, "%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", t,
            s->x[0], s->x[1], s->x[2], s->v[0], s->v[1], s->v[2], s->q[0], s->q[1], s->q[2], s->q[3],
            s->w[0], s->w[1], s->w[2]);
}

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: %s SCENARIO_JSON OUT_CSV\n", argv[0]);
        return 2;
    }
    json_path = argv[1];
    FILE *in = fopen(argv[1], "rb");
    if (!in) { fprintf(stderr, "cbody: %s: %s\n", argv[1], strerror(errno)); return 2; }
    fseek(in, 0, SEEK_END);
    long size = ftell(in);
    fseek(in, 0, SEEK_SET);
    char *text = malloc(size + 1);
    if (fread(text, 1, size, in) != (size_t)size) { fprintf(stderr, "cbody: %s: read error\n", argv[1]); return 2; }
    text[size] = 0;
    fclose(in);
    src = text;
    jnode root;
    parse_value(&root);

    scenario_t s;
    memset(&s, 0, sizeof s);
    read_scenario(&root, &s);

    FILE *out = fopen(argv[2], "w");
    if (!out) { fprintf(stderr, "cbody: %s: %s\n", argv[2], strerror(errno)); return 2; }
    fputs("t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz\n", out);
    write_row(out, 0.0, &s);
    for (long n = 1; n <= s.steps; n++) {
        step(&s);
        write_row(out, n * s.dt, &s);
    }
    if (fclose(out) != 0) { fprintf(stderr, "cbody: %s: %s\n", argv[2], strerror(errno)); return 1; }
    return 0;
}
