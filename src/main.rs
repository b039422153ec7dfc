fn main() {
    println!("cloudgi");
}
