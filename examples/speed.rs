fn main() {
    let f = pipewave::bench::forward_figures(1);
    pipewave::bench::print_figures("forward model", &f);
}
