/* SPDX-License-Identifier: MIT */
/*
 * Mesh-free Total Lagrangian Explicit Dynamics (MTLED): model setup shared by
 * every backend (lib/tled, linked by plugins/tled_cpu and plugins/tled_cuda;
 * a backend replaces only the hot loops of tled_step.h through tled_ops_t).
 *
 * Method (Horton, Wittek, Joldes, Miller 2010, "A meshless Total Lagrangian
 * explicit dynamics algorithm for surgical simulation", IJNMBE 26:977):
 *   - nodes carry the unknowns; integration points (ips) sit at the centres of
 *     a regular background grid of cells and are kept where they fall inside
 *     the domain; supports are node-based (default, support_nodal): node a
 *     has the weight radius R_a = dilation * distance to its Kn-th nearest
 *     node, and a point's support is every node whose radius reaches it, so
 *     the shape functions are one smooth set of functions of x (the legacy
 *     option takes the K nearest nodes of each evaluation point, which makes
 *     the approximation depend on where it is evaluated; see support_nodal);
 *   - moving least squares (MLS) shape functions with a linear basis and a
 *     cubic-spline weight (Belytschko et al. 1994), so linear fields are
 *     reproduced exactly;
 *   - the shape-function derivatives at the ips are corrected once so that the
 *     discrete integration constraint  sum_ip V_ip dN_a(x_ip) = G_a  holds for
 *     every node whose force is used, to TLED_CORR_RTOL (1e-13) of its
 *     uncorrected residual (tled_corr.h; the linear patch test then passes
 *     to 9.8e-10 relative in test_patch; cf. variationally consistent integration, Chen, Hillman &
 *     Rueter 2013, IJNME 95:387; G_a: see enum tled_corr).  The correction is the least-norm one that
 *     keeps linear reproduction at every ip, and the SAME derivatives give F
 *     and the forces, so forces stay the exact gradient of a discrete strain
 *     energy (symmetric stiffness, energy-conserving explicit dynamics);
 *   - lumped masses from the weights (a partition of each ip's mass);
 *   - neo-Hookean TLED stress (tled_step.h).
 *
 * Units: the model is in SI (m, kg, s, Pa, N, J).  The plugin's ports are in
 * mm; conversion happens only at the plugin boundary (TLED_MM = 1e-3 m).
 */
#ifndef TLED_MODEL_H
#define TLED_MODEL_H

#include <stddef.h>
#include <stdint.h>

#define TLED_MM 1e-3 /* metres per millimetre */

/* node kinds: what the solver does with a node */
enum tled_kind {
	TLED_FREE = 0,   /* unknown: moves under internal forces */
	TLED_FIXED = 1,  /* brain boundary: u = 0 forever */
	TLED_DRIVEN = 2, /* tumour: displacement prescribed by the growth */
};

/* node labels at the ports (sampler convention) */
enum tled_label {
	TL_TISSUE = 0,
	TL_BOUNDARY = 1,
	TL_CSF = 2,       /* ventricles / sulci */
	TL_TUMOUR = 3,
	TL_TUMOUR_BND = 4,
	TL_SEED = 5,
};

/* Which nodes get the integration-constraint correction of the derivatives,
 *   sum_ip V_ip dN_a(x_ip) = G_a.
 * With ebc = 1 (default) the target is the boundary integral of N_a n
 * evaluated with the brain-boundary nodes (label 1) as quadrature points,
 *   G_a = sum_b Phi_a(X_b) t_b,   t_b ~ A_b n_b,
 * the t_b fitted so that sum_a G_a = 0 and sum_a X_a (x) G_a = V I (the
 * discrete divergence theorem for constant and linear fields).  With
 * node-based supports (support_nodal, default) the t_b are the boundary
 * quadrature that best reproduces (ridge least squares) the integral of
 * grad N_a over the domain computed by a fine quadrature of the
 * integration cells (2^3 Gauss points per cell, 4^3 sub-points in a cut
 * cell).  (The A_b n_b start alone kept a bias: cavity h 4, nu 0.49,
 * ip_factor 0.5, direct solve: RMS 2.8 % of u(a) against 1.6 % with the
 * fitted target and 1.8 % with no correction; bench/tled/results.md.)
 * With the essential boundary conditions collocated by Lagrange
 * multipliers (tled_solve.h) the linear patch test is then exact, because
 * G stays of the form Phi_B^T t (the reactions can balance it).
 * With ebc = 0 (legacy) the target is 0 for every non-fixed node (ALL):
 * linear patch exact, but free nodes whose shape functions reach the
 * essential boundary get distorted gradients (bench/tled/results.md). */
enum tled_corr { TLED_CORR_NONE = 0, TLED_CORR_INTERIOR = 1, TLED_CORR_ALL = 2 };

#define TLED_NPHASE 7
extern const char *const tled_phase_name[TLED_NPHASE];

enum tled_mat_id { MAT_BRAIN = 0, MAT_CSF = 1, MAT_TUMOUR = 2, MAT_N = 3 };

typedef struct tled_material {
	double E;      /* Young's modulus, Pa */
	double nu;     /* Poisson's ratio */
	double rho;    /* density, kg/m^3 */
	/* derived (tled_material_set) */
	double mu;     /* shear modulus E/(2(1+nu)), Pa */
	double kappa;  /* bulk modulus E/(3(1-2nu)), Pa */
	double lambda; /* Lame lambda kappa - 2mu/3, Pa */
	double c;      /* dilatational wave speed sqrt((lambda+2mu)/rho), m/s */
	int vol;       /* volumetric energy U(J), enum tled_vol (default 0) */
} tled_material_t;

/* The volumetric part U(J) of the strain energy (tled_step.h).  Both have
 * U(1) = U'(1) = 0 and U''(1) = kappa, so they agree to first order in the
 * strain; they differ under large compression:
 *   TLED_VOL_QUAD: U = kappa/2 (J-1)^2 (Miller et al. 2007 TLED; the
 *       pressure kappa (J-1) stays finite as J -> 0, so a soft material
 *       (CSF, kappa 4.2 Pa) is squeezed through J = 0 by any push above
 *       kappa: an inverted point);
 *   TLED_VOL_LOG: U = kappa/4 (J^2 - 1 - 2 ln J) (Simo & Taylor 1982,
 *       CMAME 35:107, eq. 3.6; the volumetric law of FEBio and ITK's
 *       neo-Hookean), pressure kappa/2 (J - 1/J) -> -inf as J -> 0: a
 *       barrier, compression costs unbounded energy before J reaches 0. */
enum tled_vol { TLED_VOL_QUAD = 0, TLED_VOL_LOG = 1 };

int tled_material_set(tled_material_t *m, double E, double nu, double rho);

typedef struct tled_model_opts {
	int support_k;          /* nodes per support domain: the K nearest
	                           (support_nodal = 0), or about 1.5 K on
	                           average (support_nodal = 1, see below) */
	double support_dilation;/* weight radius = dilation * distance to the
	                           K-th (Kn-th with support_nodal) nearest */
	double ip_factor;       /* ip grid spacing / mean node spacing */
	double merge_tol;       /* m: nodes closer than this are merged */
	int corr;               /* tled_corr: integration-constraint correction */
	int corr_coarse;        /* 1 (default): the correction's conjugate
	                           gradients are preconditioned on two levels
	                           (Jacobi + a trilinear coarse grid solved by
	                           LAPACK, tled_corr_coarse.c); 0: Jacobi
	                           only */
	int ebc;                /* 1 (default): essential boundary conditions by
	                           collocation u^h(X_c) = u_c (see tled_solve.h)
	                           and the correction targets the boundary
	                           integral; 0: legacy (nodal parameters of
	                           fixed/driven nodes prescribed, target 0) */
	int ebc_fixed;          /* with ebc: 1 (default) collocate the fixed
	                           nodes too; 0: fixed nodes keep u = 0 as
	                           nodal parameters (cheaper for large brain
	                           boundaries, O(h) error there) */
	tled_material_t mat[MAT_N];
	int nthreads;           /* OpenMP threads (<=0: runtime default) */
	int support_nodal;      /* 1 (default): node-based supports.  Node a
	                           has the weight radius R_a = dilation * the
	                           distance to its Kn-th nearest node,
	                           Kn = 1.5 K / dilation^3 (in [4, 1.5 K]), so
	                           about 1.5 K nodes cover a point (30.6 on
	                           average in the cavity test, K = 20); the
	                           support of a point x is
	                           every node with |x - X_a| < R_a.  The shape
	                           functions are then one set of smooth
	                           functions whose exact gradients the ips
	                           use.  (Covers of about K nodes have 35 %
	                           fewer entries but gave 2.4 % instead of
	                           1.6 % RMS on the cavity at h 3 and lower
	                           det F in large growth; results.md.)
	                           0 (legacy): the K nearest nodes of each
	                           evaluation point with a radius depending on
	                           that point: the ips, the nodal rows and the
	                           collocation points each see a different
	                           approximation, which biased the cavity test
	                           by ~1.5-4 % of u(a) at every node spacing
	                           (bench/tled/results.md, round 4) */
	/* Domain test for ip candidates (reference coordinates, m).  NULL: the
	 * default test (near the node cloud and on the inner side of the brain
	 * boundary nodes).  Returns 1 inside, 0 outside. */
	int (*inside)(const double x[3], void *ctx);
	void *inside_ctx;
	/* Optional material per ip (reference coordinates, m): returns a
	 * tled_mat_id, or -1 to use the default (label of the nearest node). */
	int (*material)(const double x[3], void *ctx);
	void *material_ctx;
	/* 1: the geometry only, what says where things are and which nodes
	 * can move, not how they move: the merged nodes (X, label, kind,
	 * rep), the spacing, the boundary normals, the integration points
	 * and their supports (ipptr, ipnode, entip, nptr, nent) with the
	 * lumped masses (the orphans fixed, as in a full build), ebc flags
	 * and dt_wave; no shape functions (N, dN NULL), nodal rows nor
	 * correction, so no solver can run on it.  The growth at push_mm 0
	 * (tled_grow.c: nothing moves) builds this; the same arithmetic as
	 * a full build for every field it sets.  0 (default): the model. */
	int geometry_only;
} tled_model_opts_t;

/* Write a printf-style message to err (n bytes) and return -1: the error
 * helper of lib/tled's sources. */
int tled_errf(char *err, size_t n, const char *fmt, ...)
	__attribute__((format(printf, 3, 4)));

void tled_model_opts_default(tled_model_opts_t *o);

/* Uniform grid hash for nearest-neighbour queries (3-D points). */
typedef struct tled_grid {
	double lo[3], cell;      /* origin and cell size, m */
	int nc[3];
	int64_t *start;          /* ncells+1 */
	int64_t *idx;            /* point ids sorted by cell */
	const double *p;         /* 3*n points (not owned) */
	int64_t n;
} tled_grid_t;

int tled_grid_build(tled_grid_t *g, const double *p, int64_t n, double cell);
void tled_grid_free(tled_grid_t *g);
/* k nearest points to x (excluding id `skip`, -1 none); writes up to k ids
 * sorted by distance and their squared distances; returns how many. */
int tled_grid_knn(const tled_grid_t *g, const double x[3], int k, int64_t skip,
		  int64_t *ids, double *d2);

typedef struct tled_model {
	/* ---- nodes (after merging coincident ones) ---- */
	int64_t n;          /* model nodes */
	double *X;          /* 3n reference positions, m */
	int32_t *label;     /* n labels (port convention, current) */
	uint8_t *kind;      /* n tled_kind */
	double *mass;       /* n lumped masses, kg */
	double *nn_dist;    /* n distance to the nearest other node, m */
	int64_t n_in;       /* input nodes */
	int64_t *rep;       /* n_in: input node -> model node */
	int64_t n_merged;   /* input nodes merged into another */
	double h_min;       /* smallest node spacing (nn distance), m */
	double h_mean;      /* mean nn distance, m */

	/* ---- integration points ---- */
	int64_t nip;
	double *ipX;        /* 3*nip reference positions, m */
	double *ipV;        /* nip volumes (weights), m^3 */
	int32_t *ipmat;     /* nip tled_mat_id */
	double t_phase[TLED_NPHASE]; /* wall s of each build phase
	                                (tled_phase_name) */
	double *ipg;        /* nip isotropic growth stretch g (NULL: 1
	                       everywhere; front = expand).  F = F_e F_g,
	                       F_g = g I: the stress is that of F_e = F / g
	                       (Rodriguez, Hoger & McCulloch 1994, J Biomech
	                       27:455), see tled_ip_stress_c */
	int64_t *ipptr;     /* nip+1: CSR into the support arrays */
	int64_t *ipnode;    /* support node ids */
	int64_t *entip;     /* ip of each support entry */
	double *N;          /* shape function values N_a(x_ip) */
	double *dN;         /* 3 per entry: corrected dN_a/dX at x_ip, 1/m */
	double ip_h;        /* background cell size, m */
	/* transposed CSR: for node a, the support entries e with ipnode[e]==a */
	int64_t *nptr;      /* n+1 */
	int64_t *nent;      /* entries */
	/* the same entries stored in node order for the force gather
	 * (tled_gather_c, tled_cuda's k_gather): gdN[3t..] = dN[3 nent[t]..],
	 * gip[t] = entip[nent[t]].  Read in sequence instead of through nent,
	 * so the gather's one random access is the stress VP of the ip.
	 * Built by tled_model_build after the correction; NULL in a model made
	 * by hand (the gather then reads through nent: the same sums) */
	double *gdN;        /* 3 per entry, 1/m */
	int64_t *gip;       /* entries */
	/* 32-bit copies of ipnode and gip for the host's step loops
	 * (tled_step.c: 4 B less read per entry in each of the stress and the
	 * gather, which are bound by memory bandwidth on 16 cores); built with
	 * gdN when n and nip fit, else NULL (the loops read the 64-bit ones) */
	int32_t *ipn32, *gip32;
	/* the host's fused forces (tled_forces_fused_c): the ips in fb_n
	 * blocks of fb_size consecutive ips (fixed by nip, not by the thread
	 * count); block b's distinct support nodes have slots fb_ptr[b] ..
	 * fb_ptr[b+1]-1 (first appearance in ip order), fb_loc[e] is entry
	 * e's slot within its block; node a's slots, in block order, are
	 * fs_slot[fs_ptr[a] .. fs_ptr[a+1]-1].  fb_buf (3 per slot), fb_w (2
	 * per block) and fb_i (3 per block) are the evaluation's scratch.
	 * Built with gdN when ipn32 is; NULL otherwise (stress + gather). */
	int64_t fb_n, fb_size;
	int32_t *fb_loc;
	int64_t *fb_ptr, *fs_ptr, *fs_slot;
	double *fb_buf, *fb_w;
	int64_t *fb_i;

	tled_material_t mat[MAT_N];
	int nthreads;

	/* brain boundary (label 1 nodes) for the domain and contact tests */
	int64_t nb;
	int64_t *bnode;     /* nb model node ids */
	double *bX;         /* 3*nb positions, m */
	double *bn;         /* 3*nb outward unit normals */
	tled_grid_t bgrid;  /* over bX */

	/* essential boundary conditions by collocation (ebc = 1) */
	int ebc;
	int ebc_fixed;
	int rk;             /* entries per nodal row (node-based supports:
	                       the largest cover; shorter rows are padded
	                       with Phi = 0 entries) */
	int64_t *rid;       /* n*rk: support nodes of u^h at X_a */
	double *rN;         /* n*rk: shape functions Phi_b(X_a) */
	double *bt;         /* 3*nb: boundary weights t_b ~ A_b n_b (m^2),
	                       fitted so that the discrete divergence theorem
	                       holds for constant and linear fields (node-
	                       based supports: fitted to the fine-quadrature
	                       target first, see enum tled_corr) */

	/* node-based supports (support_nodal = 1) */
	int support_nodal;
	double *Ra;         /* n weight radii, m (NULL when legacy) */
	double Ra_max;      /* largest R_a, m */
	int Kn;             /* neighbour rank defining R_a */

	/* diagnostics of the setup */
	double corr_rel;    /* |integration-constraint residual| after / before */
	int corr_iters;     /* CG iterations of the correction */
	int64_t corr_nc;    /* coarse unknowns of its preconditioner (0: none) */
	double t_coarse;    /* s: coarse assembly + Cholesky, within the
	                       correction's phase time */
	double t_csolve;    /* s: the CG's coarse solves (R A_c^-1 R^T r) */
	double t_capply;    /* s: the CG's operator applications */
	double dt_wave;     /* h_min / c_max, s */
	uint64_t gen;       /* build number, unique per process: a backend
	                       that copies the model (tled_cuda) re-uploads
	                       when it changes */
} tled_model_t;

/*
 * Build the model from reference nodes X (3*n, m) and their labels.
 * `kind0` may be NULL: then label 1 -> TLED_FIXED, others TLED_FREE
 * (the caller sets TLED_DRIVEN later).  Nodes whose kind stays TLED_FIXED for
 * the whole run do not get the integration-constraint correction; pass
 * `constrain` (n flags, 1 = the node's force is used some time) or NULL
 * (= every node that is not TLED_FIXED in kind0/labels).
 * err receives a message naming the problem on failure.
 */
int tled_model_build(tled_model_t *m, const double *X, const int32_t *label,
		     int64_t n, const uint8_t *kind0, const uint8_t *constrain,
		     const tled_model_opts_t *o, char *err, size_t errsize);
void tled_model_free(tled_model_t *m);

/* The next build number (tled_model_t.gen; unique per process). */
uint64_t tled_model_next_gen(void);

/*
 * Model reuse (tled_model_cache.c).  A search of the push depth grows the
 * same nodes with the same parameters once per depth; the model does not
 * depend on the depth.  tled_model_hash: 64-bit FNV-1a of every array and
 * setting of a model (not its timings, build number or scratch), equal for
 * equal builds; tled_model_opts_hash folds a build's settings into h (not
 * the callbacks' contexts: the caller hashes what they read).
 * tled_model_copy: a deep copy (0, or -1 out of memory, d empty); every
 * array of tled_model_t must be listed in its TLED_MODEL_ARRAYS.
 * The cache keeps a copy of one model, as built.  tled_model_cache_get: 1
 * and *m a copy of it (with a new build number, and the ip_factor its
 * build used) when the key matches; when another thread of this process
 * is building the model of this key, it waits for it first; else 0, and
 * *publish = 1 when the caller is to build it and then either
 * tled_model_cache_put it (a copy is kept, waiters wake) or
 * tled_model_cache_abandon the key (a waiter builds it instead).
 * tled_model_cache_clear frees the kept model; tled_model_cache_hits
 * counts the copies handed out in this process.
 */
#define TLED_HASH_INIT UINT64_C(14695981039346656037)

uint64_t tled_hash_bytes(uint64_t h, const void *p, size_t n);
uint64_t tled_model_hash(const tled_model_t *m);
uint64_t tled_model_opts_hash(uint64_t h, const tled_model_opts_t *o);
int tled_model_copy(tled_model_t *d, const tled_model_t *s);
int tled_model_cache_get(uint64_t key, tled_model_t *m, double *ip_factor,
			 int *publish);
void tled_model_cache_put(uint64_t key, const tled_model_t *m,
			  double ip_factor);
void tled_model_cache_abandon(uint64_t key);
void tled_model_cache_clear(void);
uint64_t tled_model_cache_hits(void);

/* MLS shape functions (linear basis, cubic-spline weight) at x from the
 * support nodes ids[0..k-1] of X, weight radius R.  Writes N[k], dN[3k]
 * (uncorrected), w[k].  Returns 0, or -1 if the moment matrix is singular
 * (support nodes coplanar or coincident). */
int tled_mls(const double *X, const int64_t *ids, int k, const double x[3],
	     double R, double *N, double *dN, double *w);

/* MLS as tled_mls with node-based supports: support node i has its own
 * weight radius Ra[i] (m), basis scale L (m).  Nodes with zero weight get
 * N = dN = 0.  Returns 0 or -1 (singular moment matrix). */
int tled_mls_nodal(const double *X, const int64_t *ids, int k,
		   const double x[3], const double *Ra, double L, double *N,
		   double *dN, double *w);

/* cubic spline weight W(r), r = d/R, and dW/dr */
double tled_weight(double r, double *dwdr);

/* Sum over ips of V * dN_a (3n): the integration-constraint residual. */
/* (re)build gdN and gip from nent, entip and dN: 0, or -1 out of memory */
int tled_model_gather_index(tled_model_t *m);
/* builds (0; -1 out of memory, then none) or frees the fused forces'
 * blocks (without them the forces take stress + gather) */
int tled_model_fb_build(tled_model_t *m);
void tled_model_fb_free(tled_model_t *m);
void tled_model_gradsum(const tled_model_t *m, double *g);

/* Signed distance of y (m) beyond the brain boundary, measured along the
 * outward normal of the nearest boundary node (>0 outside).  Returns -INF
 * when the model has no boundary nodes; *bid gets that node (or -1). */
double tled_boundary_side(const tled_model_t *m, const double y[3],
			  int64_t *bid);

/* Nodes covering x with node-based supports (m->Ra set): every node a of
 * the grid g (built over m->X) with |x - X_a| < R_a, written to *ids
 * (grown with realloc, capacity *cap); returns how many, -1 when out of
 * memory. */
int tled_model_cover(const tled_model_t *m, const tled_grid_t *g,
		     const double x[3], int64_t **ids, int *cap);

/* Approximated displacement u^h(x) = sum_a N_a(x) u_a (u: 3n nodal
 * parameters, m) at a reference point x (m).  Support as at the ips: the
 * K nearest nodes of the grid ng (built over m->X), weight radius
 * dil * distance to the K-th (node-based supports: the nodes covering x,
 * K and dil unused).  MLS does not interpolate, so at a node
 * u^h(X_a) != u_a in general: outputs must use this.  Returns 0, or -1 when
 * the support is singular (out left at 0). */
int tled_model_interp(const tled_model_t *m, const tled_grid_t *ng, int K,
		      double dil, const double x[3], const double *u,
		      double out[3]);

/* Displacement gradient at every ip from nodal u (3n, m): H (9 per ip,
 * row-major dU_i/dX_j).  Used by tests and diagnostics. */
void tled_model_grad(const tled_model_t *m, const double *u, double *H);

/* out = sum_i Phi_i(X_a0) v_{rid_i}: the nodal row of node a0 applied to
 * a 3n vector v (u^h(X_a0) when v holds the nodal parameters) */
static inline void tled_model_row(const tled_model_t *m, int64_t a0,
				  const double *v, double out[3])
{
	out[0] = out[1] = out[2] = 0;
	for (int i = 0; i < m->rk; i++) {
		int64_t a = m->rid[(int64_t)m->rk * a0 + i];
		double N = m->rN[(int64_t)m->rk * a0 + i];
		for (int c = 0; c < 3; c++)
			out[c] += N * v[3 * a + c];
	}
}

#endif
