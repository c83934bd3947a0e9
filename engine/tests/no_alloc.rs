//! Steady-state stepping allocates nothing: a counting global allocator around `step`.
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

mod common;
use ukemi_engine::{State, Workspace, set_minimal, step};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

std::thread_local! {
    // Count only the test thread: libtest's own threads allocate concurrently (that made the
    // test flaky). A const-initialised Cell<bool> has no destructor and never allocates.
    static COUNTING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if COUNTING.with(|c| c.get()) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn stepping_a_chain_allocates_nothing() {
    let model = common::chain(20, 0.01);
    let mut state = State::reference(&model);
    set_minimal(&model, &mut state, &[0.3; 20], &[0.0; 20]).unwrap();
    let mut ws = Workspace::new(&model);
    step(&model, &mut state, &mut ws, &[]).unwrap();
    let before = ALLOCS.load(Ordering::Relaxed);
    COUNTING.with(|c| c.set(true));
    for _ in 0..100 {
        step(&model, &mut state, &mut ws, &[]).unwrap();
    }
    COUNTING.with(|c| c.set(false));
    assert_eq!(
        ALLOCS.load(Ordering::Relaxed) - before,
        0,
        "allocations during 100 steps"
    );
}

#[test]
fn stepping_into_a_tendon_limit_allocates_nothing() {
    let xml = r#"<mujoco><worldbody>
      <body><joint name="h1" axis="0 1 0"/><geom fromto="0 0 0 0 0 -0.4" size="0.04" type="capsule"/>
        <body pos="0 0 -0.4"><joint name="h2" axis="0 1 0"/>
          <geom fromto="0 0 0 0 0 -0.4" size="0.04" type="capsule"/></body></body></worldbody>
      <tendon><fixed limited="true" range="-0.3 0.3">
        <joint joint="h1" coef="0.5"/><joint joint="h2" coef="-0.5"/></fixed></tendon>
      <actuator><motor joint="h1"/><motor joint="h2"/></actuator></mujoco>"#;
    let model = ukemi_engine::mjcf::load_str(xml, "t.xml").unwrap().model;
    let mut state = State::reference(&model);
    let mut ws = Workspace::new(&model);
    step(&model, &mut state, &mut ws, &[-3.0, 3.0]).unwrap();
    let before = ALLOCS.load(Ordering::Relaxed);
    COUNTING.with(|c| c.set(true));
    for _ in 0..200 {
        step(&model, &mut state, &mut ws, &[-3.0, 3.0]).unwrap();
    }
    COUNTING.with(|c| c.set(false));
    assert!(
        state.tendon_impulse(&model)[0] > 0.0,
        "the limit must be reached"
    );
    assert_eq!(
        ALLOCS.load(Ordering::Relaxed) - before,
        0,
        "allocations during 200 steps"
    );
}
