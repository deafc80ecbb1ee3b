/* The C ABI of the compiled kernel of tensegrity_stiffness (libtensegrity_stiffness_kernel.so).
 *
 * One header for the library (src/joint_kernel.cpp, src/chain_kernel.cpp include it) and for its
 * callers: tensegrity_stiffness/mechanics/kernel.py mirrors it with ctypes, and
 * test/kernel/test_kernel_abi.py holds that mirror to the library (tsk_abi_version,
 * tsk_joint_model_layout, the buffer sizes).
 *
 * Conventions:
 * - every entry point returns int64_t: TSK_OK (0) or a negative TSK_ERROR_* code (sizes and the
 *   version are non-negative values); no C++ exception crosses this boundary (a failed
 *   allocation is TSK_ERROR_INTERNAL);
 * - arrays are row-major float64 (flags: bytes 0 / 1) that the caller owns and keeps alive for
 *   the whole call; lengths are in elements; counts (strings, screws, joints, series terms) must
 *   be >= 1 and every output buffer is at least the size the call needs, else
 *   TSK_ERROR_COUNT / TSK_ERROR_BUFFER_SIZE and nothing is written;
 * - no global state: everything a call reads comes through its arguments.
 */
#ifndef TENSEGRITY_STIFFNESS__KERNEL_H_
#define TENSEGRITY_STIFFNESS__KERNEL_H_

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Version of this ABI: bumped with every change below (1: the series tables set through a
 * global tsk_set_series, positive return values as screw indices; 2: without
 * tsk_joint_measure_packed; 3: without tsk_joint_linear_model, tsk_joint_pose_terms,
 * tsk_qp_warm_face and tsk_joint_transform; 4: without tsk_filter_body_dynamics,
 * tsk_filter_propagate and tsk_filter_update). */
#define TSK_ABI_VERSION 5

/* Status codes. */
#define TSK_OK 0
#define TSK_ERROR_NULL_POINTER (-1)        /* a required pointer is null */
#define TSK_ERROR_COUNT (-2)               /* a count is < 1 */
#define TSK_ERROR_BUFFER_SIZE (-3)         /* a buffer is shorter than the call needs, or rest
                                              lengths are neither n nor n x n_screws */
#define TSK_ERROR_ARGUMENT (-4)            /* an unknown mode, force law or output selection */
#define TSK_ERROR_ZERO_LENGTH (-5)         /* a string shorter than min_string_length */
#define TSK_ERROR_SINGULAR_SYSTEM (-6)     /* tsk_chain_tip: the 6N x 6N system is singular;
                                              tsk_joint_linear_model: the mass matrix is */
#define TSK_ERROR_SINGULAR_COMPLIANCE (-7) /* tsk_chain_tip: the tip compliance is singular */
#define TSK_ERROR_INTERNAL (-8)            /* a C++ exception, caught at the boundary */

/* Evaluation modes: everything; K without K_c; the wrench alone (K, K_c not written). */
#define TSK_MODE_FULL 0
#define TSK_MODE_STIFFNESS 1
#define TSK_MODE_WRENCH 2

/* Force laws: Hooke k (l - l0); the paper's k (l - l0) / l (mechanics/joint.py's FORCE_LAWS). */
#define TSK_LAW_HOOKE 0
#define TSK_LAW_PAPER 1

/* Rows of the series table: the Taylor coefficients of a, b, c, b1, c1 (geometry/screw.py). */
#define TSK_SERIES_ROWS 5

/* Outcomes of tsk_qp_warm_face (a value in its buffer): the face is optimal; it is not (the
 * solution leaves the box or A t = b, or a multiplier is negative); its KKT system is singular
 * or solved inaccurately (the caller's least squares decides). */
#define TSK_FACE_OPTIMAL 0
#define TSK_FACE_REJECTED 1
#define TSK_FACE_SINGULAR 2

/* Outputs of tsk_chain_tip besides the tip wrench (a bit mask). */
#define TSK_TIP_BASE 1
#define TSK_TIP_TOOL 2

/* One joint model: pointers into arrays the caller keeps alive while the model is used. */
typedef struct tsk_joint_model {
  int64_t n_strings;          /* n >= 1 */
  const double* p1;           /* n x 3, link-1 end of each string in {1} (m) */
  const double* p2;           /* n x 3, link-2 end of each string in {2} (m) */
  const double* k;            /* n, stiffness (N/m) */
  const double* max_stretch;  /* n, lmax - l0 (m; inf for no limit) */
  int64_t law;                /* TSK_LAW_* */
  int64_t series_terms;       /* terms per row of series, >= 1 */
  const double* series;       /* TSK_SERIES_ROWS x series_terms: coefficients in theta^2 of a,
                                 b, c, b1, c1, highest power first (geometry/screw.py) */
  double series_threshold;    /* angles below it take the series (screw.SERIES_THRESHOLD) */
  double min_string_length;   /* shorter strings: TSK_ERROR_ZERO_LENGTH (joint.MIN_STRING_LENGTH) */
} tsk_joint_model;

/* Fields of tsk_joint_model in declaration order (indices into tsk_joint_model_layout). */
#define TSK_MODEL_FIELDS 10

/* TSK_ABI_VERSION of the library. */
int64_t tsk_abi_version(void);

/* sizeof(tsk_joint_model), then the offsetof of its TSK_MODEL_FIELDS fields in declaration
 * order, written to out (capacity >= 1 + TSK_MODEL_FIELDS); returns the number written. */
int64_t tsk_joint_model_layout(int64_t* out, int64_t capacity);

/* Doubles of the packed buffer of one screw for n strings: the inputs xi 6 and the rest
 * lengths n, then the outputs T 16, s 3n, lengths n, tensions n, wrench 6, K 36, K_c 36, then
 * slack n and saturated n as bytes (rounded up to whole doubles). */
int64_t tsk_joint_packed_size(int64_t n_strings);

/* One screw, everything in one buffer (buf_len >= tsk_joint_packed_size(n)): it holds xi and
 * the rest lengths on entry and the outputs after. */
int64_t tsk_joint_evaluate_packed(const tsk_joint_model* model, int64_t mode, double* buf,
                                  int64_t buf_len);

/* Doubles of the measurement buffer of one screw for n strings: the SE(3) left Jacobian
 * J = [[G, 0], [Q, G]] (36), the pose Jacobian P = d[dp; dtheta]/dxi = [[D, G], [G, 0]] (36,
 * D = Q - hat(t) G), then dl/dxi (n x 6), dphi/dxi (n x 6) and dphi/dl (n) of the strings. */
int64_t tsk_joint_measure_size(int64_t n_strings);

/* tsk_joint_evaluate_packed (same buf, mode and errors), and the string measurements'
 * Jacobians in meas (meas_len >= tsk_joint_measure_size(n)): the compiled twin of
 * sensor_models.string_predictions_unchecked (and pose_jacobian). */
int64_t tsk_joint_measure_packed(const tsk_joint_model* model, int64_t mode, double* buf,
                                 int64_t buf_len, double* meas, int64_t meas_len);

/* Doubles of the linear-model buffer of one screw for n strings (tsk_joint_linear_model): the
 * input W (6), then F + W (6), J_l (36), M = J_b^T G J_b (36), the right-hand sides
 * R = [J_l^T Pi K | -L^T C L | J_l^T Pi dF/dl0 | J_l^T Pi] (6 x (18 + n), row-major), M^-1 R
 * (the same shape) and the equilibrium flag (1). */
int64_t tsk_joint_linear_size(int64_t n_strings);

/* The linear model of link 2's dynamics at one screw with zero velocity
 * (mechanics/joint_dynamics.py, JointDynamics.linearize at an equilibrium):
 * tsk_joint_evaluate_packed (same buf; K without K_c), then in lin
 * (lin_len >= tsk_joint_linear_size(n); it holds the external wrench W, [f; m]
 * in {1}, on entry) the blocks above, with J_b = J_l(-xi), G = inertia (6 x 6 spatial inertia
 * about {2}'s origin, twists [w; v]), Pi the swap of the 3-blocks, L = dl/dxi (n x 6), C =
 * diag(damping) (n values N s/m, or null: no damping, that block 0) and dF/dl0 the rest-length
 * derivative of the wrench. The flag is 1 when |F + W|_max <= equilibrium_tolerance
 * max(max tension, 1e-300) (the blocks are then the linear model; elsewhere the derivatives of
 * J and M, not computed here, add to the first block), else 0. Errors: those of the
 * evaluation, TSK_ERROR_ARGUMENT for a negative or NaN tolerance, TSK_ERROR_SINGULAR_SYSTEM. */
int64_t tsk_joint_linear_model(const tsk_joint_model* model, const double* inertia,
                               const double* damping, double equilibrium_tolerance, double* buf,
                               int64_t buf_len, double* lin, int64_t lin_len);

/* T = exp(hat(xi)) (eq. 2) of one screw with the model's series tables: buf (buf_len >= 22)
 * holds xi (6) on entry and T (16, row-major 4 x 4) after it; the same formulas as the
 * evaluation's (and geometry/screw.py's exp_se3). */
int64_t tsk_joint_transform(const tsk_joint_model* model, double* buf, int64_t buf_len);

/* Doubles of the pose-terms buffer for n strings: the input T (16, row-major 4 x 4 pose of
 * link 2 in {1}), then the string lengths (n), B (6 x n, row-major: column j the wrench [f; m]
 * of string j per unit tension), K0 (36) and M (n x 36) with K_c(t) = K0 + sum_j t_j M_j. */
int64_t tsk_joint_pose_terms_size(int64_t n_strings);

/* What stays fixed at a pose for the tension QP of the stiffness controller (control/
 * controller.py, pose_terms_at; eqs. 7-11), into buf (buf_len >= tsk_joint_pose_terms_size(n);
 * it holds T on entry). TSK_ERROR_ZERO_LENGTH (outputs partly written) for a string shorter
 * than min_string_length. */
int64_t tsk_joint_pose_terms(const tsk_joint_model* model, double* buf, int64_t buf_len);

/* Doubles of the warm-face buffer of a QP with n variables and m equalities: the inputs P
 * (n x n), c (n), A (m x n), b (m), lo (n), hi (n), the start t0 (n), the working set at_lo (n)
 * and at_hi (n) as 0 / 1 (at most one set per variable), then the outputs t (n), nu (m) and the
 * outcome (1, a TSK_FACE_* value). */
int64_t tsk_qp_face_size(int64_t n, int64_t m);

/* Step 1 of the stiffness controller's warm-started QP (control/controller.py, solve_box_qp):
 * min 1/2 t'Pt - c't s.t. A t = b, lo <= t <= hi on the face of the working set. t starts at
 * lo / hi on the working set, t0 elsewhere; the free entries and nu solve the face's KKT system
 * [[P_FF, A_F'], [A_F, 0]] [t_F; nu] = [c_F - P_FX t_X; b - A_X t_X]. TSK_FACE_SINGULAR when
 * that system is singular or its residual exceeds residual_tolerance (1 + |rhs|_max);
 * TSK_FACE_OPTIMAL (t clipped to the box) when lo - s <= t <= hi + s (s = bound_slack
 * max(1, |hi - lo|)), |A t - b|_2 <= feasibility_tolerance and every multiplier of the working
 * set is >= -multiplier_tolerance max(1, |P|_max, |c|_max); else TSK_FACE_REJECTED (also with no
 * free variable). Errors: null buf, counts (n < 1, m < 0), a short buffer, a negative or NaN
 * tolerance (TSK_ERROR_ARGUMENT). */
int64_t tsk_qp_warm_face(int64_t n, int64_t m, double feasibility_tolerance,
                         double multiplier_tolerance, double residual_tolerance,
                         double bound_slack, double* buf, int64_t buf_len);

/* Doubles of the output buffer of a batch: blocks of all screws one after the other, T 16N,
 * s 3nN, lengths nN, tensions nN, wrench 6N, K 36N, K_c 36N, then slack nN and saturated nN as
 * bytes (rounded up to whole doubles). */
int64_t tsk_joint_batch_size(int64_t n_strings, int64_t n_screws);

/* A batch of n_screws screws xi (n_screws x 6); rest: n values for every screw (rest_len n) or
 * a row of n per screw (rest_len n x n_screws); out (out_len >= tsk_joint_batch_size) as above.
 * On TSK_ERROR_ZERO_LENGTH the outputs are partly written. */
int64_t tsk_joint_evaluate(const tsk_joint_model* model, int64_t n_screws, const double* xi,
                           const double* rest, int64_t rest_len, int64_t mode, double* out,
                           int64_t out_len);

/* Frames of an n-joint spine from its joint transforms T (n x 16): out (out_len >= 32n + 16)
 * receives P (n x 16, the poses of {1}_i), L (n x 16, those of {2}_i) and the tool's pose (16);
 * offsets (n - 1) x 16 (null when n == 1), tool 16. */
int64_t tsk_chain_frames(int64_t n_joints, const double* T, const double* offsets,
                         const double* tool, double* out, int64_t out_len);

/* The tip of an n-joint spine at an evaluated configuration: P, L (n x 16), tip (16), joint
 * wrenches F (n x 6, each in {1}_i), K_c (n x 36). weights: null, or the link weights m_k g
 * (n x 3) with the centres of mass coms (n x 3, in {2}_k). W_in: the tip wrench (6, base), or
 * null for the implied one, -Ad_{P_N}^-T F_N - w_N. out (out_len >= 78): the tip wrench used
 * (6), then K_tip in the base frame (36, when outputs has TSK_TIP_BASE) and in the tool frame
 * (36, TSK_TIP_TOOL). */
int64_t tsk_chain_tip(int64_t n_joints, const double* P, const double* L, const double* tip,
                      const double* F, const double* Kc, const double* weights,
                      const double* coms, const double* W_in, int64_t outputs, double* out,
                      int64_t out_len);

/* Doubles of tsk_filter_body_dynamics' output: dxi/dt (6), dV/dt (6), J_b^-1 (36), the
 * Jacobians of dV/dt in the screw (36), the twist (36) and the load (36). */
#define TSK_FILTER_BODY_SIZE 156

/* The joint filter's equations of motion in {2} (estimation/joint_filter.py, body_dynamics) at
 * one screw: T (16), the SE(3) left Jacobian J (36), dl/dxi (n x 6, read when damped), the
 * strings' wrench F [f; m] (6) and K (36) there, link 2's body twist [w; v] (6), the load
 * [f; m] (6), the spatial inertia G (36) and its inverse (36), the string damping (n, N s/m,
 * read when damped == 1). out (out_len >= TSK_FILTER_BODY_SIZE) as above. Errors: n < 1, null
 * pointers, a short buffer, damped not 0 / 1 (TSK_ERROR_ARGUMENT), a singular SO(3) Jacobian
 * (TSK_ERROR_SINGULAR_SYSTEM). */
int64_t tsk_filter_body_dynamics(int64_t n_strings, int64_t damped, const double* T,
                                 const double* J, const double* length_jacobian,
                                 const double* wrench, const double* stiffness,
                                 const double* twist, const double* load, const double* inertia,
                                 const double* inertia_inverse, const double* damping,
                                 double* out, int64_t out_len);

/* Doubles of tsk_filter_propagate's buffer for a state of size 12 or 18: the state x (size)
 * and its covariance P (size x size), both updated in place, then the step of x (size) and the
 * rate f (12) it was made with. */
int64_t tsk_filter_propagate_size(int64_t size);

/* One linearly implicit trapezoidal (Rosenbrock) step of h seconds of the filter's state
 * [xi; V (; W)] (JointFilter._substep): dynamics is a tsk_filter_body_dynamics output at the
 * linearisation point, dx (size, or null) the correction since it (f + A dx), twist_density
 * (6) and load_density (6, read when size == 18) the process noise's variances per second.
 * x += (I - h/2 A)^-1 h f, P = Phi P Phi^T + Q (symmetrised) with Phi = (I - h/2 A)^-1 (I +
 * h/2 A). Errors: size not 12 / 18 (TSK_ERROR_COUNT), null pointers, a short buffer, h not
 * finite and > 0 (TSK_ERROR_ARGUMENT), a singular step matrix (TSK_ERROR_SINGULAR_SYSTEM). */
int64_t tsk_filter_propagate(int64_t size, double h, const double* dynamics, const double* dx,
                             const double* twist_density, const double* load_density,
                             double* buf, int64_t buf_len);

/* Doubles of tsk_filter_update's buffer: P (size x size), the whitened residual r = h(x) - z
 * (rows), its Jacobian H (rows x size), then the outputs NIS (1), the correction (size) and the
 * updated covariance (size x size). */
int64_t tsk_filter_update_size(int64_t size, int64_t rows);

/* The stacked whitened EKF update with every row kept (kalman_update): S = H P H^T + I,
 * nu = -r, NIS = nu^T S^-1 nu, dx = (H P)^T S^-1 nu, P - (H P)^T S^-1 H P (symmetrised).
 * Errors: counts, null buf, a short buffer, a singular S (TSK_ERROR_SINGULAR_SYSTEM). */
int64_t tsk_filter_update(int64_t size, int64_t rows, double* buf, int64_t buf_len);

/* Readings of tsk_filter_motion_rows (a bit mask; rows in this order, 3 each). */
#define TSK_FILTER_SPECIFIC_FORCE 1
#define TSK_FILTER_GRAVITY 2
#define TSK_FILTER_GYRO 4
/* Doubles of tsk_filter_motion_rows' input: T (16), the SE(3) left Jacobian J (36), link 2's
 * body twist (6), gravity in {1} (3), then each reading's value and whitening weights (3 + 3):
 * specific force, gravity direction, gyro. */
#define TSK_FILTER_MOTION_INPUT 79

/* The whitened rows r = (h(x) - z) w (3 per reading) and their Jacobian H (3 per reading x
 * size, row-major, every column written) of the accelerometer (specific force f = dv/dt + w x v
 * - R^T g with dv/dt of the dynamics, a tsk_filter_body_dynamics output), the gravity direction
 * -f / |f| and the gyro (w) (JointFilter._rows). Returns the rows written (>= 0) or an error:
 * size not 12 / 18 (TSK_ERROR_COUNT), null pointers, readings outside the mask or a negative
 * min_gravity_norm, |f| below min_gravity_norm with a gravity reading (TSK_ERROR_ARGUMENT). */
int64_t tsk_filter_motion_rows(int64_t size, int64_t readings, double min_gravity_norm,
                               const double* in, const double* dynamics, double* r, double* H);

/* Doubles of tsk_filter_output's output: the pose covariance (36), the twist [dp/dt; w] in {1}
 * (6) and its covariance (36). */
#define TSK_FILTER_OUTPUT_SIZE 78

/* The joint filter's estimate of its state (JointFilter._estimate): from the state x (its
 * first 12: screw, body twist [w; v]) with covariance P (size x size, size >= 12), T at the
 * screw and the pose Jacobian (36): the pose covariance Pj C Pj^T (C = P[:6, :6]), the twist
 * [R v; R w] and its first-order covariance (both symmetrised). Errors: size < 12, null
 * pointers, a short buffer. */
int64_t tsk_filter_output(int64_t size, const double* P, const double* x, const double* T,
                          const double* pose_jacobian, double* out, int64_t out_len);

#ifdef __cplusplus
}
#endif

#endif  /* TENSEGRITY_STIFFNESS__KERNEL_H_ */
