//! What keeps a busy coordinator's answers small: `GET /api/v1/jobs` in pages.

use super::*;

#[test]
fn jobs_are_listed_in_pages_newest_first() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let ids: Vec<String> = (0..3)
        .map(|seed| {
            let settings = json!({"integrator": "pt", "spp": 1, "seed": seed});
            let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml.clone()), vec![], settings);
            assert_eq!(status, 201, "{job}");
            job["id"].as_str().unwrap().to_string()
        })
        .collect();
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let page = |query: &str| {
        rt.block_on(async {
            let r = rest::client(None).get(format!("{}/api/v1/jobs{query}", c.url)).send().await.unwrap();
            let header = |name: &str| r.headers().get(name).map(|v| v.to_str().unwrap().to_string());
            let (total, link) = (header("x-total-count"), header("link"));
            (r.status().as_u16(), total, link, r.json::<Value>().await.unwrap_or(Value::Null))
        })
    };
    let listed = |body: &Value| -> Vec<String> {
        body.as_array().unwrap().iter().map(|j| j["id"].as_str().unwrap().to_string()).collect()
    };
    let (status, total, link, body) = page("?limit=2");
    assert_eq!((status, total.as_deref()), (200, Some("3")));
    assert_eq!(listed(&body), [ids[2].clone(), ids[1].clone()], "newest first");
    assert_eq!(link.as_deref(), Some("</api/v1/jobs?limit=2&offset=2>; rel=\"next\""));
    let (_, _, link, body) = page("?limit=2&offset=2");
    assert_eq!((listed(&body), link), (vec![ids[0].clone()], None));
    assert_eq!(listed(&page("").3).len(), 3, "a default page holds them all");
    let (status, _, _, body) = page("?limit=0");
    assert_eq!(status, 400, "{body}");
}
