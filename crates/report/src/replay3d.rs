//! The 3D replay in the report: per scene, the reference's mean wrist and
//! cube against each source's over time, drawn by a small canvas renderer
//! inlined in the page (no library, no network): a time slider, a play
//! button, drag to rotate, wheel to zoom, a checkbox per source.
//!
//! The data is the comparison's own per-step series (each source's mean
//! wrist position, and for scenes with a cube its mean pose), in whole
//! millimetres and, for orientations, 3 decimals: about 30 kB per source and
//! scene.
//!
//! Other studies add scenes of their own ([`ExtraScene`]): the cube tosses
//! add a few tosses, the real cube (black) against each source's, a cube
//! drawn at every recorded sample.
//!
//! The page reads its location's hash: `#replay=S:T` shows the replay
//! alone, at scene index `S` and `T` seconds (for links and screenshots).

use crate::figures::{LineStyle, SourceStyles};
use realitygap_analysis::compare::{SceneReport, SourceSummary};
use std::fmt::Write;

/// The cube's edge drawn when the scene has a cube, metres (the study's
/// cube; the comparison does not carry the scene's geometry).
pub const CUBE_EDGE_M: f64 = 0.075;

fn mm(v: f64) -> String {
    format!("{}", (v * 1000.0).round() as i64)
}

fn push_track(out: &mut String, points: &[Option<[f64; 3]>]) {
    out.push('[');
    for (i, p) in points.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        match p {
            Some(p) if p.iter().all(|v| v.is_finite()) => {
                let _ = write!(out, "{},{},{}", mm(p[0]), mm(p[1]), mm(p[2]));
            }
            _ => out.push_str("null,null,null"),
        }
    }
    out.push(']');
}

fn push_quats(out: &mut String, q: &[Option<[f64; 4]>]) {
    out.push('[');
    for (i, q) in q.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        match q {
            Some(q) if q.iter().all(|v| v.is_finite()) => {
                let _ = write!(out, "{:.3},{:.3},{:.3},{:.3}", q[0], q[1], q[2], q[3]);
            }
            _ => out.push_str("null,null,null,null"),
        }
    }
    out.push(']');
}

fn json_str(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into())
}

/// A source's opening: `{"name":..,"kind":..,"color":..,"dash":..,"reference":..`
/// (its tracks follow, then `}`).
fn push_source_head(out: &mut String, name: &str, kind: &str, style: &LineStyle, reference: bool) {
    let _ = write!(
        out,
        "{{\"name\":{},\"kind\":{},\"color\":\"{}\",\"dash\":{},\"reference\":{}",
        json_str(name),
        json_str(kind),
        style.hex(),
        style
            .dash
            .map_or("[]".into(), |(a, b)| format!("[{a},{b}]")),
        reference
    );
}

fn push_source(out: &mut String, s: &SourceSummary, style: &LineStyle, reference: bool) {
    push_source_head(out, &s.source, &s.kind, style, reference);
    out.push_str(",\"wrist\":");
    push_track(out, &s.series.wrist_mean_m);
    if !s.series.cube_mean_m.is_empty() {
        out.push_str(",\"cube\":");
        push_track(out, &s.series.cube_mean_m);
        out.push_str(",\"cubeq\":");
        push_quats(out, &s.series.cube_mean_quat);
    }
    out.push('}');
}

/// A scene of the replay from another study: a box alone, the recorded
/// one (the reference) and each source's, at the recorded samples.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExtraScene {
    /// The name in the scene menu.
    pub name: String,
    /// The time between samples, s.
    pub dt_s: f64,
    /// The box's edge, m.
    pub edge_m: f64,
    /// The recorded box first, then each source's.
    pub sources: Vec<ExtraSource>,
}

/// One box's track in an [`ExtraScene`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExtraSource {
    /// Its name in the legend.
    pub name: String,
    /// `recorded`, `simulated` or `physics-free`.
    pub kind: String,
    /// The box's centre per sample, m (`None`: no pose there).
    pub position_m: Vec<Option<[f64; 3]>>,
    /// Its orientation per sample (w, x, y, z).
    pub orientation: Vec<Option<[f64; 4]>>,
}

/// The replay's data as JSON: per scene its name, control period, steps,
/// goal, cube edge and sources (the reference first); then `extra`'s.
pub fn data_json(reports: &[SceneReport], styles: &SourceStyles, extra: &[ExtraScene]) -> String {
    let mut out = String::from("{\"scenes\":[");
    for (k, r) in reports.iter().enumerate() {
        if k > 0 {
            out.push(',');
        }
        let has_cube = std::iter::once(&r.reference)
            .chain(&r.sources)
            .any(|s| !s.series.cube_mean_m.is_empty());
        let _ = write!(
            out,
            "{{\"name\":{},\"dt\":{},\"steps\":{},\"phases\":{:?},\"goal\":{},\"cube_edge\":{},\"sources\":[",
            json_str(&r.scene),
            r.control_period_s,
            r.steps,
            r.phases_s,
            r.goal_m.map_or("null".into(), |g| format!("[{},{},{}]", mm(g[0]), mm(g[1]), mm(g[2]))),
            if has_cube { mm(CUBE_EDGE_M) } else { "null".into() }
        );
        push_source(&mut out, &r.reference, &LineStyle::REFERENCE, true);
        for s in &r.sources {
            if s.series.wrist_mean_m.iter().all(Option::is_none) {
                continue;
            }
            out.push(',');
            push_source(&mut out, s, &styles.get(&s.source), false);
        }
        out.push_str("]}");
    }
    for (k, x) in extra.iter().enumerate() {
        if k > 0 || !reports.is_empty() {
            out.push(',');
        }
        let steps = x
            .sources
            .iter()
            .map(|s| s.position_m.len())
            .max()
            .unwrap_or(0);
        let _ = write!(
            out,
            "{{\"name\":{},\"dt\":{},\"steps\":{},\"phases\":[],\"goal\":null,\"cube_edge\":{},\"sources\":[",
            json_str(&x.name),
            x.dt_s,
            steps,
            mm(x.edge_m)
        );
        for (i, src) in x.sources.iter().enumerate() {
            if i > 0 {
                out.push(',');
            }
            let reference = i == 0;
            let style = if reference {
                LineStyle::REFERENCE
            } else {
                LineStyle::for_source(i - 1)
            };
            push_source_head(&mut out, &src.name, &src.kind, &style, reference);
            out.push_str(",\"cube\":");
            push_track(&mut out, &src.position_m);
            out.push_str(",\"cubeq\":");
            push_quats(&mut out, &src.orientation);
            out.push('}');
        }
        out.push_str("]}");
    }
    out.push_str("]}");
    out
}

/// The section's HTML: the controls, the canvas, the data and the renderer;
/// `extra` scenes after the study's.
pub fn section(reports: &[SceneReport], styles: &SourceStyles, extra: &[ExtraScene]) -> String {
    let mut h = String::new();
    h.push_str("<section id=\"replay\">\n<h2>3D replay</h2>\n");
    if reports.is_empty() {
        // Tosses alone (a report of a replay's folder of tosses).
        h.push_str("<p>Single tosses: the real cube (black) and each source's, from the toss's first recorded sample, in the frame of the recording (z up, the table top at z = 0; grid lines every 0.1 m). Drag to rotate, scroll to zoom; the slider sets the time.");
    } else {
        h.push_str("<p>The mean wrist position of the reference (black, thick) and of each source over time, and for a scene with a cube the mean cube pose (drawn as a cube of the study's 0.075 m edge). Drag to rotate, scroll to zoom; the slider sets the time. Distances in the world frame of the scene (z up, the arm's base at the origin; grid lines every 0.1 m).");
        if !extra.is_empty() {
            h.push_str(" The scene menu also holds single tosses of the second study: the real cube (black) and each source's, from the toss's first recorded sample, in the frame of the recording (the table top at z = 0).");
        }
    }
    h.push_str("</p>\n");
    h.push_str("<div class=\"replay-controls\"><label>Scene <select id=\"replay-scene\"></select></label> <button type=\"button\" id=\"replay-play\">Play</button> <input type=\"range\" id=\"replay-time\" min=\"0\" max=\"0\" value=\"0\" step=\"1\" aria-label=\"time\"> <output id=\"replay-clock\">0.00 s</output></div>\n");
    h.push_str("<div class=\"replay-view\"><canvas id=\"replay-canvas\" width=\"760\" height=\"520\" aria-label=\"3D replay\"></canvas><div id=\"replay-legend\"></div></div>\n");
    let _ = writeln!(
        h,
        "<script type=\"application/json\" id=\"replay-data\">{}</script>",
        data_json(reports, styles, extra)
            .replace('<', "\\u003c")
            .replace('>', "\\u003e")
            .replace('&', "\\u0026")
    );
    let _ = writeln!(h, "<script>{SCRIPT}</script>");
    h.push_str("</section>\n");
    h
}

/// The section's style rules.
pub const CSS: &str = "
.replay-controls{display:flex;align-items:center;gap:.6rem;flex-wrap:wrap;margin:.4rem 0}
#replay-time{flex:1;min-width:240px}
.replay-view{display:flex;gap:1rem;flex-wrap:wrap;align-items:flex-start}
#replay-canvas{border:1px solid #ccc;background:#fcfcfc;cursor:grab;max-width:100%}
body.replay-only>:not(#replay){display:none}
#replay-legend label{display:block;font-size:.85rem;white-space:nowrap}
#replay-legend .swatch{display:inline-block;width:1.4em;height:.35em;margin:0 .35em .15em 0;vertical-align:middle}
";

/// The renderer: plain JavaScript on a 2D canvas, a perspective projection
/// of a camera orbiting the scene's centre.
const SCRIPT: &str = r#"
(function(){
"use strict";
var data=JSON.parse(document.getElementById('replay-data').textContent);
var canvas=document.getElementById('replay-canvas'),ctx=canvas.getContext('2d');
var sel=document.getElementById('replay-scene'),slider=document.getElementById('replay-time');
var clock=document.getElementById('replay-clock'),legend=document.getElementById('replay-legend');
var play=document.getElementById('replay-play');
var view={yaw:-0.9,pitch:0.45,zoom:1.0},scene=null,shown={},timer=null;
data.scenes.forEach(function(s,i){var o=document.createElement('option');o.value=i;o.textContent=s.name;sel.appendChild(o);});
function at(a,i,n){if(!a)return null;var v=a.slice(i*n,i*n+n);for(var k=0;k<n;k++){if(v[k]===null||v[k]===undefined)return null;}return v;}
function bounds(s){var lo=[1e9,1e9,0],hi=[-1e9,-1e9,-1e9];
 s.sources.forEach(function(src){[src.wrist,src.cube].forEach(function(a){if(!a)return;for(var i=0;i<s.steps;i++){var p=at(a,i,3);if(!p)continue;for(var k=0;k<3;k++){lo[k]=Math.min(lo[k],p[k]);hi[k]=Math.max(hi[k],p[k]);}}});});
 for(var k=0;k<2;k++){lo[k]=Math.min(lo[k],0);hi[k]=Math.max(hi[k],0);}
 return {c:[(lo[0]+hi[0])/2,(lo[1]+hi[1])/2,(lo[2]+hi[2])/2],r:Math.max(200,Math.hypot(hi[0]-lo[0],hi[1]-lo[1],hi[2]-lo[2])/2)};}
function project(p,b){var x=p[0]-b.c[0],y=p[1]-b.c[1],z=p[2]-b.c[2];
 var cy=Math.cos(view.yaw),sy=Math.sin(view.yaw),cp=Math.cos(view.pitch),sp=Math.sin(view.pitch);
 var x1=cy*x-sy*y,y1=sy*x+cy*y,depth=cp*y1-sp*z,up=sp*y1+cp*z;
 var d=4*b.r,k=Math.min(canvas.width,canvas.height)*0.45*view.zoom/b.r*d/(d+depth);
 return [canvas.width/2+x1*k,canvas.height/2-up*k];}
function line(a,b,bd){var p=project(a,bd),q=project(b,bd);ctx.beginPath();ctx.moveTo(p[0],p[1]);ctx.lineTo(q[0],q[1]);ctx.stroke();}
function rot(q,v){var w=q[0],x=q[1],y=q[2],z=q[3];
 var ix=w*v[0]+y*v[2]-z*v[1],iy=w*v[1]+z*v[0]-x*v[2],iz=w*v[2]+x*v[1]-y*v[0],iw=-x*v[0]-y*v[1]-z*v[2];
 return [ix*w+iw*-x+iy*-z-iz*-y,iy*w+iw*-y+iz*-x-ix*-z,iz*w+iw*-z+ix*-y-iy*-x];}
function cube(p,q,e,bd){var h=e/2,c=[];for(var i=0;i<8;i++){var v=[(i&1?h:-h),(i&2?h:-h),(i&4?h:-h)];var r=q?rot(q,v):v;c.push([p[0]+r[0],p[1]+r[1],p[2]+r[2]]);}
 [[0,1],[2,3],[4,5],[6,7],[0,2],[1,3],[4,6],[5,7],[0,4],[1,5],[2,6],[3,7]].forEach(function(e){line(c[e[0]],c[e[1]],bd);});}
function draw(){if(!scene)return;var s=scene,i=+slider.value,bd=bounds(s);
 ctx.clearRect(0,0,canvas.width,canvas.height);ctx.lineWidth=1;ctx.strokeStyle='#e2e2e2';
 var g0=Math.floor((bd.c[0]-bd.r*1.2)/100)*100,g1=Math.ceil((bd.c[0]+bd.r*1.2)/100)*100,h0=Math.floor((bd.c[1]-bd.r*1.2)/100)*100,h1=Math.ceil((bd.c[1]+bd.r*1.2)/100)*100;
 for(var x=g0;x<=g1;x+=100)line([x,h0,0],[x,h1,0],bd);for(var y=h0;y<=h1;y+=100)line([g0,y,0],[g1,y,0],bd);
 ctx.strokeStyle='#888';ctx.lineWidth=3;line([0,0,0],[0,0,55],bd);
 ctx.lineWidth=1.5;[['#c33',[100,0,0]],['#3a3',[0,100,0]],['#33c',[0,0,100]]].forEach(function(a){ctx.strokeStyle=a[0];line([0,0,0],a[1],bd);});
 if(s.goal){var gp=project(s.goal,bd);ctx.strokeStyle='#555';ctx.lineWidth=1;ctx.beginPath();ctx.arc(gp[0],gp[1],6,0,7);ctx.stroke();}
 var order=s.sources.slice().reverse();
 order.forEach(function(src){if(!shown[src.name])return;var w=src.reference?3:1.6;
  ctx.strokeStyle=src.color;ctx.setLineDash(src.dash||[]);ctx.globalAlpha=0.35;ctx.lineWidth=w;ctx.beginPath();var open=false;
  for(var k=0;k<s.steps;k++){var p=at(src.wrist,k,3);if(!p){open=false;continue;}var q=project(p,bd);if(open)ctx.lineTo(q[0],q[1]);else ctx.moveTo(q[0],q[1]);open=true;}
  ctx.stroke();ctx.globalAlpha=1;ctx.lineWidth=w+0.6;ctx.beginPath();open=false;
  for(var k2=Math.max(0,i-20);k2<=i;k2++){var p2=at(src.wrist,k2,3);if(!p2){open=false;continue;}var q2=project(p2,bd);if(open)ctx.lineTo(q2[0],q2[1]);else ctx.moveTo(q2[0],q2[1]);open=true;}
  ctx.stroke();ctx.setLineDash([]);var pn=at(src.wrist,i,3);if(pn){var pp=project(pn,bd);ctx.fillStyle=src.color;ctx.beginPath();ctx.arc(pp[0],pp[1],src.reference?6:4.5,0,7);ctx.fill();}
  if(s.cube_edge&&src.cube){var cp=at(src.cube,i,3);if(cp){ctx.strokeStyle=src.color;ctx.lineWidth=src.reference?2.5:1.2;cube(cp,at(src.cubeq,i,4),s.cube_edge,bd);}}
 });
 clock.textContent=(i*s.dt).toFixed(2)+' s';}
function pickScene(k){scene=data.scenes[k];sel.value=k;slider.max=scene.steps-1;if(+slider.value>scene.steps-1)slider.value=scene.steps-1;
 legend.innerHTML='';scene.sources.forEach(function(src){if(shown[src.name]===undefined)shown[src.name]=src.reference||src.kind!=='recorded';
  var l=document.createElement('label'),c=document.createElement('input');c.type='checkbox';c.checked=shown[src.name];
  c.addEventListener('change',function(){shown[src.name]=c.checked;draw();});var sw=document.createElement('span');sw.className='swatch';sw.style.background=src.dash&&src.dash.length?'repeating-linear-gradient(90deg,'+src.color+' 0 '+src.dash[0]+'px,transparent '+src.dash[0]+'px '+(src.dash[0]+src.dash[1])+'px)':src.color;
  l.appendChild(c);l.appendChild(sw);l.appendChild(document.createTextNode(src.name));legend.appendChild(l);});draw();}
sel.addEventListener('change',function(){pickScene(+sel.value);});
slider.addEventListener('input',draw);
play.addEventListener('click',function(){if(timer){clearInterval(timer);timer=null;play.textContent='Play';return;}
 play.textContent='Pause';timer=setInterval(function(){var v=+slider.value+1;if(v>+slider.max){clearInterval(timer);timer=null;play.textContent='Play';return;}slider.value=v;draw();},scene.dt*1000);});
var drag=null;canvas.addEventListener('mousedown',function(e){drag=[e.clientX,e.clientY];canvas.style.cursor='grabbing';});
window.addEventListener('mouseup',function(){drag=null;canvas.style.cursor='grab';});
window.addEventListener('mousemove',function(e){if(!drag)return;view.yaw+=(e.clientX-drag[0])*0.01;view.pitch=Math.max(-1.5,Math.min(1.5,view.pitch+(e.clientY-drag[1])*0.01));drag=[e.clientX,e.clientY];draw();});
canvas.addEventListener('wheel',function(e){e.preventDefault();view.zoom=Math.max(0.3,Math.min(5,view.zoom*Math.exp(-e.deltaY*0.001)));draw();},{passive:false});
var m=/replay=(\d+):([0-9.]+)/.exec(location.hash);
pickScene(m?Math.min(+m[1],data.scenes.length-1):0);
if(m){document.body.classList.add('replay-only');slider.value=Math.round(+m[2]/scene.dt);draw();}
})();
"#;

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_analysis::testing as testdata;

    #[test]
    fn the_data_holds_every_source_in_millimetres() {
        let mut r = testdata::scene();
        r.sources[0].series.cube_mean_m = vec![Some([0.5, 0.0, 0.0375]); 100];
        r.sources[0].series.cube_mean_quat = vec![Some([1.0, 0.0, 0.0, 0.0]); 100];
        let styles = SourceStyles::for_reports(std::slice::from_ref(&r));
        let json = data_json(std::slice::from_ref(&r), &styles, &[]);
        let v: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
        let scene = &v["scenes"][0];
        assert_eq!(scene["steps"], 100);
        assert_eq!(scene["cube_edge"], 75);
        let sources = scene["sources"].as_array().unwrap();
        assert_eq!(sources[0]["reference"], true);
        assert_eq!(sources[0]["name"], "real");
        // 100 steps of x, y, z.
        assert_eq!(sources[0]["wrist"].as_array().unwrap().len(), 300);
        let with_cube = sources.iter().find(|s| s.get("cube").is_some()).unwrap();
        assert_eq!(with_cube["cube"][0], 500);
        assert_eq!(with_cube["cubeq"].as_array().unwrap().len(), 400);
        // The source whose runs all diverged has no track and is left out.
        assert!(sources.iter().all(|s| s["name"] != "Dead"), "{json}");
    }

    #[test]
    fn the_section_cannot_close_its_script_early() {
        let mut r = testdata::scene();
        r.sources[0].source = "</script><b>x".into();
        let styles = SourceStyles::for_reports(std::slice::from_ref(&r));
        let html = section(std::slice::from_ref(&r), &styles, &[]);
        assert!(!html.contains("</script><b>"), "{html}");
        assert!(html.contains("id=\"replay-time\""));
    }

    /// A scene of another study follows the study's: its boxes' tracks in
    /// millimetres, the recorded one first and drawn as the reference.
    #[test]
    fn an_extra_scene_follows_with_its_boxes() {
        let r = testdata::scene();
        let styles = SourceStyles::for_reports(std::slice::from_ref(&r));
        let track = |x: f64| ExtraSource {
            name: format!("at {x}"),
            kind: "simulated".into(),
            position_m: vec![Some([x, 0.0, 0.05]), None, Some([x, 0.1, 0.05])],
            orientation: vec![Some([1.0, 0.0, 0.0, 0.0]), None, Some([1.0, 0.0, 0.0, 0.0])],
        };
        let toss = ExtraScene {
            name: "toss 7".into(),
            dt_s: 1.0 / 148.0,
            edge_m: 0.1048,
            sources: vec![track(0.2), track(0.3)],
        };
        let json = data_json(
            std::slice::from_ref(&r),
            &styles,
            std::slice::from_ref(&toss),
        );
        let v: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
        let scene = &v["scenes"][1];
        assert_eq!(scene["name"], "toss 7");
        assert_eq!(scene["steps"], 3);
        assert_eq!(scene["cube_edge"], 105);
        assert_eq!(scene["sources"][0]["reference"], true);
        assert_eq!(scene["sources"][0]["color"], "#000000");
        assert_eq!(scene["sources"][1]["cube"][0], 300);
        assert!(scene["sources"][1]["cube"][3].is_null());
        assert_eq!(scene["sources"][1]["cubeq"].as_array().unwrap().len(), 12);
        // Alone (no scene of the arm) it is still valid JSON.
        let alone = data_json(&[], &styles, std::slice::from_ref(&toss));
        assert!(
            serde_json::from_str::<serde_json::Value>(&alone).is_ok(),
            "{alone}"
        );
    }
}
